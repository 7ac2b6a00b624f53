//! The addresses of the `fil` board's markers, from the ELF's symbol table (ELF32,
//! little-endian: what the thumbv7em target links).

use anyhow::{Context, bail, ensure};

fn u16_at(b: &[u8], o: usize) -> anyhow::Result<u16> {
    let s = b.get(o..o + 2).context("truncated ELF")?;
    Ok(u16::from_le_bytes([s[0], s[1]]))
}

fn u32_at(b: &[u8], o: usize) -> anyhow::Result<u32> {
    let s = b.get(o..o + 4).context("truncated ELF")?;
    Ok(u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
}

/// The section header table of a little-endian ELF32 file: (offset, entry size, count).
fn section_table(elf: &[u8]) -> anyhow::Result<(usize, usize, usize)> {
    ensure!(
        elf.get(..6) == Some(&[0x7F, b'E', b'L', b'F', 1, 1][..]),
        "not a little-endian ELF32 file"
    );
    Ok((
        u32_at(elf, 0x20)? as usize,
        u16_at(elf, 0x2E)? as usize,
        u16_at(elf, 0x30)? as usize,
    ))
}

/// Every function symbol `(name, address with the Thumb bit cleared)`.
pub fn function_symbols(elf: &[u8]) -> anyhow::Result<Vec<(String, u32)>> {
    let (shoff, shentsize, shnum) = section_table(elf)?;
    let section = |i: usize| -> anyhow::Result<(u32, usize, usize, usize)> {
        let o = shoff + i * shentsize;
        Ok((
            u32_at(elf, o + 4)?,
            u32_at(elf, o + 16)? as usize,
            u32_at(elf, o + 20)? as usize,
            u32_at(elf, o + 24)? as usize,
        ))
    };
    let mut out = Vec::new();
    for i in 0..shnum {
        let (ty, off, size, link) = section(i)?;
        if ty != 2 {
            continue; // SHT_SYMTAB
        }
        let (_, stroff, strsize, _) = section(link)?;
        let strtab = elf.get(stroff..stroff + strsize).context("string table")?;
        for s in (off..off + size).step_by(16) {
            let name = u32_at(elf, s)? as usize;
            let value = u32_at(elf, s + 4)?;
            let info = *elf.get(s + 12).context("symbol")?;
            if info & 0xF != 2 {
                continue; // STT_FUNC
            }
            let rest = strtab.get(name..).context("symbol name")?;
            let end = rest.iter().position(|&c| c == 0).unwrap_or(rest.len());
            out.push((
                String::from_utf8_lossy(&rest[..end]).into_owned(),
                value & !1,
            ));
        }
    }
    Ok(out)
}

/// The address of the one function whose (mangled) name contains `needle`.
pub fn address_of(symbols: &[(String, u32)], needle: &str) -> anyhow::Result<u32> {
    let hits: Vec<_> = symbols.iter().filter(|(n, _)| n.contains(needle)).collect();
    match hits.as_slice() {
        [(_, a)] => Ok(*a),
        [] => bail!("no function `{needle}` in the firmware image (not a `fil` build?)"),
        _ => bail!("several functions match `{needle}`"),
    }
}

/// The plugin's marker addresses: tick_begin, tick_end, fake_enter, fake_exit.
pub fn markers(elf: &[u8]) -> anyhow::Result<[u32; 4]> {
    let syms = function_symbols(elf)?;
    Ok([
        address_of(&syms, "3fil10tick_begin")?,
        address_of(&syms, "3fil8tick_end")?,
        address_of(&syms, "3fil10fake_enter")?,
        address_of(&syms, "3fil9fake_exit")?,
    ])
}

/// Size of every section by name.
pub fn section_sizes(elf: &[u8]) -> anyhow::Result<Vec<(String, u64)>> {
    let (shoff, shentsize, shnum) = section_table(elf)?;
    let shstrndx = u16_at(elf, 0x32)? as usize;
    let hdr = |i: usize| shoff + i * shentsize;
    let str_off = u32_at(elf, hdr(shstrndx) + 16)? as usize;
    let mut out = Vec::new();
    for i in 0..shnum {
        let name = u32_at(elf, hdr(i))? as usize;
        let size = u64::from(u32_at(elf, hdr(i) + 20)?);
        let rest = elf.get(str_off + name..).context("section name")?;
        let end = rest.iter().position(|&c| c == 0).unwrap_or(rest.len());
        out.push((String::from_utf8_lossy(&rest[..end]).into_owned(), size));
    }
    Ok(out)
}

/// Flash and static RAM of an image, as firmware/scripts/fw-size.sh counts them: flash =
/// .vector_table + .text + .rodata + .data (its load image), static RAM = .data + .bss +
/// .uninit.
pub fn flash_and_ram(elf: &[u8]) -> anyhow::Result<(u64, u64)> {
    let mut flash = 0;
    let mut ram = 0;
    for (name, size) in section_sizes(elf)? {
        match name.as_str() {
            ".vector_table" | ".text" | ".rodata" => flash += size,
            ".data" => {
                flash += size;
                ram += size;
            }
            ".bss" | ".uninit" => ram += size,
            _ => {}
        }
    }
    Ok((flash, ram))
}
