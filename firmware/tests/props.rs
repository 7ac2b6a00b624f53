//! Property tests of the firmware's wire formats, on the host: every frame the chips can
//! send decodes back to what was encoded, every corrupted bit is caught, and the replay
//! table's configuration block round-trips.

use paragyro_core::Config;
use paragyro_firmware::drivers::ads131m08::{CHANNELS, Frame, RawCode};
use paragyro_firmware::drivers::adxl355::raw20_from_bytes;
use paragyro_firmware::replay::accel_bytes;
use paragyro_firmware::table::{config_from_slots, config_slots};
use proptest::prelude::*;

fn frame_strategy() -> impl Strategy<Value = Frame> {
    (
        any::<u16>(),
        proptest::array::uniform8(-0x80_0000i32..=0x7F_FFFF),
    )
        .prop_map(|(response, codes)| {
            let mut f = Frame {
                response,
                ..Frame::default()
            };
            for (c, v) in f.codes.iter_mut().zip(codes) {
                *c = RawCode::saturating_new(v);
            }
            f
        })
}

proptest! {
    /// ADS131M08: `decode(encode(f)) == f` for any STATUS word and any eight 24-bit codes.
    #[test]
    fn ads131m08_frames_round_trip(f in frame_strategy()) {
        let bytes = f.encode();
        prop_assert_eq!(Frame::decode(&bytes), Ok(f));
        prop_assert_eq!(f.codes.len(), CHANNELS);
    }

    /// ADS131M08: one flipped bit anywhere in the CRC-covered words (or in the CRC word
    /// itself) is a CRC error, never a silently wrong frame.
    #[test]
    fn ads131m08_one_flipped_bit_is_caught(f in frame_strategy(), word in 0usize..10, bit in 0usize..16) {
        let mut bytes = f.encode();
        // the 16 meaningful bits of a 24-bit word are its first two bytes for the response
        // and CRC words; for a code word every bit counts (use the top 16)
        let at = word * 3 + bit / 8;
        bytes[at] ^= 1 << (bit % 8);
        prop_assert!(Frame::decode(&bytes).is_err(), "flip at byte {} bit {} decoded", at, bit % 8);
    }

    /// ADXL355: the three data bytes of any 20-bit code read back as that code.
    #[test]
    fn adxl355_codes_round_trip(code in -0x8_0000i32..=0x7_FFFF) {
        prop_assert_eq!(raw20_from_bytes(accel_bytes(code)), code);
    }

    /// The replay table's configuration block: `config_from_slots(config_slots(c)) == c`
    /// for configurations that differ from Table 2 in any slot field.
    #[test]
    fn replay_config_slots_round_trip(
        wy2 in 0.9f64..1.1,
        centre in 20_000.0f64..23_000.0,
        dither in any::<bool>(),
        retune in any::<bool>(),
        forgetting in 0.99f64..1.0,
        stuck in 2u32..500,
        order in 1usize..5,
    ) {
        let mut c = Config::table2();
        c.nominal.wy2 = wy2;
        c.pump_centre_hz = centre;
        c.dither.enabled = dither;
        c.retune.enabled = retune;
        c.rls.forgetting = forgetting;
        c.monitor.stuck_samples = stuck;
        c.lockin_lpf_order = order;
        let slots = config_slots(&c);
        prop_assert_eq!(config_from_slots(|i| slots[i]), c);
    }
}
