//! NRRD input and output (<http://teem.sourceforge.net/nrrd/format.html>).
//!
//! NRRD is the format Parallax writes for procedural volumes and the one most
//! volume tools can exchange with it (docs/design.md "Data"). The reader handles
//! what such tools write for a 3-D scalar volume: attached (`.nrrd`) and
//! detached (`.nhdr` + `data file`) headers, `raw`, `gzip` and `ascii` encodings,
//! either byte order, `spacings` or `space directions`. The writer streams
//! slice by slice so that a volume larger than RAM can be produced.
//!
//! * [`header`]: the header (attached or detached) and what it says.
//! * [`writer`]: [`NrrdWriter`], the streaming writer.

mod header;
#[cfg(test)]
mod tests;
mod writer;

use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::Path;

use anyhow::{ensure, Context, Result};
use flate2::bufread::MultiGzDecoder;

use super::raw::{check_file_size, skip_bytes, RawSource, READ_BUFFER};

pub use header::{read_header, NrrdEncoding, NrrdHeader};
pub use writer::NrrdWriter;

/// Opens a NRRD volume (attached or detached header) for streaming.
pub fn open_nrrd(path: &Path) -> Result<RawSource> {
    let (header, attached, header_len) = read_header(path)?;
    let world = header.world;
    Ok(open_data(path, header, attached, header_len)?.with_world(world))
}

/// The data of a NRRD whose header `read_header` read.
fn open_data(
    path: &Path,
    header: NrrdHeader,
    attached: BufReader<File>,
    header_len: u64,
) -> Result<RawSource> {
    let info = header.info.clone();
    let (label, mut reader, mut pos) = match &header.data_file {
        None => (path.display().to_string(), attached, header_len),
        Some(data) => {
            let label = format!("{} (data file of {})", data.display(), path.display());
            let file = File::open(data).with_context(|| format!("{label}: cannot open"))?;
            (label, BufReader::with_capacity(READ_BUFFER, file), 0)
        }
    };
    let mut line = Vec::new();
    for n in 0..header.line_skip {
        line.clear();
        let got = reader
            .read_until(b'\n', &mut line)
            .with_context(|| format!("{label}: line skip"))?;
        ensure!(got > 0, "{label}: line skip: the file ends after {n} lines");
        pos += got as u64;
    }
    match header.encoding {
        NrrdEncoding::Raw => {
            let len = reader
                .get_ref()
                .metadata()
                .with_context(|| format!("{label}: cannot stat"))?
                .len();
            let skip = if header.byte_skip == -1 {
                // The data is the last bytes of the file.
                check_file_size(&label, &info, pos, len, false)?;
                len - pos - info.source_bytes()
            } else {
                let skip = header.byte_skip as u64;
                check_file_size(&label, &info, pos + skip, len, true)?;
                skip
            };
            skip_bytes(&mut reader, skip).with_context(|| format!("{label}: byte skip"))?;
            Ok(RawSource::from_reader(
                label,
                info,
                header.big_endian,
                false,
                Box::new(reader),
            ))
        }
        NrrdEncoding::Ascii => {
            skip_bytes(&mut reader, header.byte_skip.max(0) as u64)
                .with_context(|| format!("{label}: byte skip {}", header.byte_skip))?;
            Ok(RawSource::from_reader(label, info, false, false, Box::new(reader)).as_text())
        }
        NrrdEncoding::Bzip2 => stream(
            label,
            &header,
            true,
            bzip2::read::MultiBzDecoder::new(reader),
        ),
        NrrdEncoding::Hex => {
            let dec = HexReader {
                inner: reader,
                label: label.clone(),
            };
            stream(label, &header, false, dec)
        }
        NrrdEncoding::Gzip => stream(label, &header, true, MultiGzDecoder::new(reader)),
    }
}

/// A decoding stream (gzip, bzip2, hex) past its byte skip, as a source;
/// `compressed` streams are read to their end to check their trailer.
fn stream(
    label: String,
    header: &NrrdHeader,
    compressed: bool,
    mut dec: impl std::io::Read + Send + 'static,
) -> Result<RawSource> {
    skip_bytes(&mut dec, header.byte_skip.max(0) as u64)
        .with_context(|| format!("{label}: byte skip {}", header.byte_skip))?;
    Ok(RawSource::from_reader(
        label,
        header.info.clone(),
        header.big_endian,
        compressed,
        Box::new(dec),
    ))
}

/// Bytes written as pairs of hexadecimal digits (NRRD `encoding: hex`),
/// white space anywhere.
struct HexReader<R> {
    inner: R,
    label: String,
}

impl<R: BufRead> std::io::Read for HexReader<R> {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        let mut n = 0;
        let mut pair = [0u8; 2];
        let mut have = 0;
        while n < out.len() {
            let buf = self.inner.fill_buf()?;
            if buf.is_empty() {
                if have == 1 {
                    return Err(std::io::Error::new(
                        std::io::ErrorKind::InvalidData,
                        format!("{}: an odd number of hex digits", self.label),
                    ));
                }
                break;
            }
            let mut used = 0;
            for &c in buf {
                if n == out.len() {
                    break;
                }
                used += 1;
                if c.is_ascii_whitespace() {
                    continue;
                }
                let Some(d) = (c as char).to_digit(16) else {
                    return Err(std::io::Error::new(
                        std::io::ErrorKind::InvalidData,
                        format!("{}: '{}' is not a hex digit", self.label, c.escape_ascii()),
                    ));
                };
                pair[have] = d as u8;
                have += 1;
                if have == 2 {
                    out[n] = pair[0] << 4 | pair[1];
                    n += 1;
                    have = 0;
                }
            }
            self.inner.consume(used);
            if n > 0 && have == 0 {
                break;
            }
        }
        Ok(n)
    }
}
