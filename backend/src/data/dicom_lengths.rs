//! A DICOM file's element lengths checked against its size before dicom-rs
//! reads it: the parser allocates (and zeroes) an element's declared length
//! before reading its value, so a 2 KB file declaring a 4 GB value would
//! take 4 GB of memory to be refused. Here the file is walked element by
//! element (PS3.5 §7: the meta group in explicit VR little endian, then the
//! data set in its transfer syntax's; items and sequences of undefined
//! length walked into, encapsulated pixel data's fragments skipped by
//! their lengths), and a length that runs past the end of the file is
//! refused, naming the element. A deflated data set is not walked (its
//! bytes are compressed).

use anyhow::{bail, Result};

const ITEM: (u16, u16) = (0xFFFE, 0xE000);
const ITEM_END: (u16, u16) = (0xFFFE, 0xE00D);
const SEQUENCE_END: (u16, u16) = (0xFFFE, 0xE0DD);
const PIXEL_DATA: (u16, u16) = (0x7FE0, 0x0010);
const TRANSFER_SYNTAX: (u16, u16) = (0x0002, 0x0010);
const UNDEFINED: u32 = 0xFFFF_FFFF;

/// Explicit VRs whose length is 4 bytes after 2 reserved ones: all but
/// the short ones (PS3.5 Table 7.1-2). An unknown VR is read as UN, as
/// dicom-rs reads it.
fn long_vr(vr: &[u8]) -> bool {
    !matches!(
        vr,
        b"AE"
            | b"AS"
            | b"AT"
            | b"CS"
            | b"DA"
            | b"DS"
            | b"DT"
            | b"FL"
            | b"FD"
            | b"IS"
            | b"LO"
            | b"LT"
            | b"PN"
            | b"SH"
            | b"SL"
            | b"SS"
            | b"ST"
            | b"TM"
            | b"UI"
            | b"UL"
            | b"US"
    )
}

#[derive(Clone, Copy)]
struct Encoding {
    explicit: bool,
    big: bool,
}

/// Checks the lengths of `bytes`, a Part 10 file (preamble and `DICM`).
pub fn check(label: &str, bytes: &[u8]) -> Result<()> {
    if bytes.len() < 132 || &bytes[128..132] != b"DICM" {
        return Ok(()); // dicom-rs says what is wrong
    }
    let mut pos = 132;
    let meta = Encoding {
        explicit: true,
        big: false,
    };
    let mut syntax = String::new();
    // The meta group (0002,xxxx).
    while pos + 4 <= bytes.len() && u16::from_le_bytes([bytes[pos], bytes[pos + 1]]) == 0x0002 {
        let (tag, header, len) = element(label, bytes, pos, meta)?;
        if len == UNDEFINED {
            bail!(
                "{label}: meta element ({:04X},{:04X}) has an undefined length",
                tag.0,
                tag.1
            );
        }
        if tag == TRANSFER_SYNTAX {
            let v = &bytes[pos + header..pos + header + len as usize];
            syntax = String::from_utf8_lossy(v)
                .trim_end_matches(['\0', ' '])
                .to_string();
        }
        pos += header + len as usize;
    }
    let data = match syntax.as_str() {
        "1.2.840.10008.1.2" => Encoding {
            explicit: false,
            big: false,
        },
        "1.2.840.10008.1.2.2" => Encoding {
            explicit: true,
            big: true,
        },
        // Deflated: compressed bytes, not walked.
        "1.2.840.10008.1.2.1.99" => return Ok(()),
        _ => meta,
    };
    walk(label, bytes, pos, data)
}

/// Walks the data set from `pos` to the end of the file.
fn walk(label: &str, bytes: &[u8], mut pos: usize, enc: Encoding) -> Result<()> {
    let mut fragments = false;
    while pos + 8 <= bytes.len() {
        let tag = (u16_at(bytes, pos, enc.big), u16_at(bytes, pos + 2, enc.big));
        if tag.0 == 0xFFFE {
            // Items and delimiters: a tag and a 4-byte length, no VR.
            let len = u32_at(bytes, pos + 4, enc.big);
            pos += 8;
            if len != UNDEFINED {
                fits(label, bytes, pos, tag, len)?;
            }
            // A delimiter's length should be 0; dicom-rs reads what it
            // declares as a value, and so it is skipped here.
            let defined = if len == UNDEFINED { 0 } else { len as usize };
            if tag == SEQUENCE_END {
                fragments = false;
                pos += defined;
            } else if tag == ITEM_END {
                pos += defined;
            } else if tag == ITEM {
                // A fragment's bytes are skipped; an item's data set is
                // walked into.
                if fragments {
                    pos += defined;
                }
            } else {
                bail!(
                    "{label}: ({:04X},{:04X}) is not an item or delimiter tag",
                    tag.0,
                    tag.1
                );
            }
            continue;
        }
        let (tag, header, len) = element(label, bytes, pos, enc)?;
        let sequence = enc.explicit && &bytes[pos + 4..pos + 6] == b"SQ";
        pos += header;
        if len == UNDEFINED {
            // A sequence (or UN holding one), or encapsulated pixel data.
            fragments = tag == PIXEL_DATA;
        } else if !sequence {
            pos += len as usize;
        }
    }
    Ok(())
}

/// An element's tag, header size and declared value length at `pos`,
/// checked to fit in the file.
fn element(
    label: &str,
    bytes: &[u8],
    pos: usize,
    enc: Encoding,
) -> Result<((u16, u16), usize, u32)> {
    let tag = (u16_at(bytes, pos, enc.big), u16_at(bytes, pos + 2, enc.big));
    let (header, len) = if enc.explicit {
        if pos + 8 > bytes.len() {
            bail!(
                "{label}: the file ends inside the header of element ({:04X},{:04X})",
                tag.0,
                tag.1
            );
        }
        if long_vr(&bytes[pos + 4..pos + 6]) {
            if pos + 12 > bytes.len() {
                bail!(
                    "{label}: the file ends inside the header of element ({:04X},{:04X})",
                    tag.0,
                    tag.1
                );
            }
            (12, u32_at(bytes, pos + 8, enc.big))
        } else {
            (8, u16_at(bytes, pos + 6, enc.big) as u32)
        }
    } else {
        (8, u32_at(bytes, pos + 4, enc.big))
    };
    if len != UNDEFINED {
        fits(label, bytes, pos + header, tag, len)?;
    }
    Ok((tag, header, len))
}

fn fits(label: &str, bytes: &[u8], at: usize, tag: (u16, u16), len: u32) -> Result<()> {
    let left = bytes.len().saturating_sub(at);
    if len as usize > left {
        bail!(
            "{label}: element ({:04X},{:04X}) declares {len} bytes of value, but the file has {left} left",
            tag.0,
            tag.1
        );
    }
    Ok(())
}

fn u16_at(b: &[u8], at: usize, big: bool) -> u16 {
    let v = [b[at], b[at + 1]];
    if big {
        u16::from_be_bytes(v)
    } else {
        u16::from_le_bytes(v)
    }
}

fn u32_at(b: &[u8], at: usize, big: bool) -> u32 {
    let v = [b[at], b[at + 1], b[at + 2], b[at + 3]];
    if big {
        u32::from_be_bytes(v)
    } else {
        u32::from_le_bytes(v)
    }
}
