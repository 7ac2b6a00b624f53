//! Stack measurement of the QEMU boards: paint the free stack at boot, find the high-water
//! mark after the run (the replay's and the loop's stack figures).

const PAINT: u32 = 0x5A5A_A5A5;

unsafe extern "C" {
    static _stack_end: u32;
    static _stack_start: u32;
}

/// The stack region: (lowest address, top).
pub fn stack_bounds() -> (usize, usize) {
    // only the addresses of the linker symbols are taken
    (
        core::ptr::addr_of!(_stack_end) as usize,
        core::ptr::addr_of!(_stack_start) as usize,
    )
}

/// Paints the RAM between the statics and the live stack (call first thing in `main`).
#[inline(never)]
pub fn paint_stack() {
    let (lo, _) = stack_bounds();
    // leave 256 bytes below the current frame alone
    let hi = cortex_m::register::msp::read() as usize - 256;
    let mut a = (lo + 3) & !3;
    while a < hi {
        // SAFETY: RAM between the statics and the live stack is unused at this point.
        unsafe { core::ptr::write_volatile(a as *mut u32, PAINT) };
        a += 4;
    }
}

/// The deepest the stack has reached since [`paint_stack`], bytes.
pub fn stack_high_water() -> usize {
    let (lo, top) = stack_bounds();
    let mut a = (lo + 3) & !3;
    // SAFETY: reading RAM inside the stack region.
    while a < top && unsafe { core::ptr::read_volatile(a as *const u32) } == PAINT {
        a += 4;
    }
    top - a
}
