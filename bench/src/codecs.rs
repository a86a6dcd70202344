//! `parallax bench codecs`: the compression ratio and the encode and decode
//! speed of every brick codec on the quantised bricks of each volume.

use crate::measure::{self, write_table};
use anyhow::Result;
use parallax_backend::store::codec::{self, Codec};
use parallax_backend::store::{self, BrickEncoding, ImportOptions};
use std::path::Path;
use std::time::Instant;

/// One codec on one volume's bricks (`parallax bench codecs`).
#[derive(Clone, Debug)]
pub struct CodecPoint {
    pub volume: String,
    pub codec: String,
    /// Bytes of the source volume, of the quantised bricks before
    /// compression, and of the stored bricks.
    pub source_bytes: u64,
    pub raw_bytes: u64,
    pub stored_bytes: u64,
    /// One thread, MB/s of quantised bytes in (encode) and out (decode).
    pub encode_mb_s: f64,
    pub decode_mb_s: f64,
    /// Decode speed in MB/s of stored bytes read: what the disk must beat
    /// for decoding to be the bottleneck.
    pub decode_in_mb_s: f64,
}

/// The codecs `parallax bench codecs` compares.
pub fn codec_candidates() -> Vec<Codec> {
    [
        "lz4",
        "lz4+delta",
        "lz4+auto",
        "zstd1",
        "zstd2",
        "zstd3",
        "zstd1+delta",
        "zstd2+delta",
        "zstd3+delta",
        "zstd1+auto",
        "zstd2+auto",
        "zstd3+auto",
    ]
    .iter()
    .map(|s| Codec::parse(s).expect("a known codec"))
    .collect()
}

/// Imports each volume (bricks of 32, `encoding`), then compresses and
/// decompresses its quantised bricks with every candidate codec on one
/// thread, timing each; writes `codecs.csv` in `out`.
pub fn run(
    volumes: &[std::path::PathBuf],
    encoding: BrickEncoding,
    out: &Path,
) -> Result<Vec<CodecPoint>> {
    measure::create_out(out)?;
    let tmp = tempfile::tempdir()?;
    let mut points = Vec::new();
    for path in volumes {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let mut src = parallax_backend::data::open(path, None)?;
        let source_bytes = src.info().source_bytes();
        let db_path = tmp.path().join("codec-bench.pxo");
        let opts = ImportOptions {
            encoding,
            codec: Codec::LZ4,
            ..Default::default()
        };
        store::import(src.as_mut(), &db_path, &name, &opts)?;
        let db = store::OctreeDb::open(&db_path)?;
        let len = db.layout().stored_len() * bytes_per(encoding);
        let mut raws = Vec::new();
        for n in db.nodes.iter().filter(|n| n.is_stored()) {
            let stored = db.read_stored(n.key)?.expect("stored");
            raws.push(
                codec::decompress(&stored, encoding, len, db.framing())
                    .map_err(|e| anyhow::anyhow!("{name}: brick {}: {e}", n.key))?,
            );
        }
        let raw_bytes: u64 = raws.iter().map(|r| r.len() as u64).sum();
        for c in codec_candidates() {
            let t = Instant::now();
            let stored: Vec<Vec<u8>> = raws
                .iter()
                .map(|r| codec::compress(r, encoding, c))
                .collect();
            let enc_s = t.elapsed().as_secs_f64();
            let stored_bytes: u64 = stored.iter().map(|s| s.len() as u64).sum();
            // Decode several times for a stable figure on a busy machine.
            let reps = 3;
            let t = Instant::now();
            for _ in 0..reps {
                for (s, r) in stored.iter().zip(&raws) {
                    let d = codec::decompress(s, encoding, len, codec::Framing::Tagged)
                        .map_err(|e| anyhow::anyhow!("{name}: {}: {e}", c.name()))?;
                    anyhow::ensure!(&d == r, "{name}: {} is not lossless", c.name());
                }
            }
            let dec_s = t.elapsed().as_secs_f64() / reps as f64;
            points.push(CodecPoint {
                volume: name.clone(),
                codec: c.name(),
                source_bytes,
                raw_bytes,
                stored_bytes,
                encode_mb_s: raw_bytes as f64 / 1e6 / enc_s,
                decode_mb_s: raw_bytes as f64 / 1e6 / dec_s,
                decode_in_mb_s: stored_bytes as f64 / 1e6 / dec_s,
            });
        }
    }
    write_table(
        &out.join("codecs.csv"),
        "volume,codec,source_bytes,raw_brick_bytes,stored_bytes,ratio_to_source,ratio_to_raw,encode_mb_s,decode_mb_s,decode_in_mb_s",
        points.iter().map(|p| {
            format!(
                "{},{},{},{},{},{:.3},{:.3},{:.1},{:.1},{:.1}",
                p.volume,
                p.codec,
                p.source_bytes,
                p.raw_bytes,
                p.stored_bytes,
                p.source_bytes as f64 / p.stored_bytes as f64,
                p.raw_bytes as f64 / p.stored_bytes as f64,
                p.encode_mb_s,
                p.decode_mb_s,
                p.decode_in_mb_s
            )
        }),
    )?;
    Ok(points)
}

fn bytes_per(encoding: BrickEncoding) -> usize {
    match encoding {
        BrickEncoding::U8Range => 1,
        BrickEncoding::U16Range => 2,
        BrickEncoding::F32 => 4,
    }
}

/// Prints the codecs' table.
pub fn print(points: &[CodecPoint]) {
    println!("volume                 codec         ratio  encode MB/s  decode MB/s (in)");
    for p in points {
        println!(
            "{:<22} {:<12} {:>6.2}  {:>11.0}  {:>11.0} ({:.0})",
            p.volume,
            p.codec,
            p.source_bytes as f64 / p.stored_bytes as f64,
            p.encode_mb_s,
            p.decode_mb_s,
            p.decode_in_mb_s
        );
    }
}
