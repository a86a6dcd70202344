//! clap value parsers shared by the commands: each argument is parsed into
//! its type, and a bad value is reported by clap with the flag's name.

use parallax_backend::data::synth::SynthKind;
use parallax_backend::store::codec::Codec;
use parallax_backend::store::BrickEncoding;
use parallax_backend::volume::VoxelType;
use std::path::PathBuf;

/// The scene a command shows and the display it shows it on (`render`,
/// `serve`).
#[derive(clap::Args)]
pub struct SceneDisplay {
    #[arg(long)]
    pub scene: PathBuf,
    /// Display file (default: the scene's `display`).
    #[arg(long)]
    pub display: Option<PathBuf>,
}

pub fn synth_kind(s: &str) -> Result<SynthKind, String> {
    SynthKind::parse(s).ok_or_else(|| {
        "expected marschner-lobb, shells, shepp-logan, constant, plane, noise, stiff or ct".into()
    })
}

pub fn voxel_type(s: &str) -> Result<VoxelType, String> {
    VoxelType::parse(s).ok_or_else(|| "expected u8, i8, u16, i16, u32, i32, f32 or f64".into())
}

pub fn encoding(s: &str) -> Result<BrickEncoding, String> {
    BrickEncoding::parse(s).ok_or_else(|| "expected u8, u16 or none".into())
}

pub fn layout(s: &str) -> Result<parallax_common::wall::Layout, String> {
    match s {
        "arc" => Ok(parallax_common::wall::Layout::Arc),
        "line" => Ok(parallax_common::wall::Layout::Line),
        _ => Err("expected arc or line".into()),
    }
}

/// `WxH`.
pub fn size<T: std::str::FromStr>(s: &str) -> Result<[T; 2], String> {
    let (a, b) = s.split_once('x').ok_or("expected WxH, e.g. 160x120")?;
    let p = |t: &str| {
        t.trim()
            .parse::<T>()
            .map_err(|_| format!("'{t}' is not a number"))
    };
    Ok([p(a)?, p(b)?])
}

/// `N` comma-separated numbers.
pub fn list<T: std::str::FromStr, const N: usize>(s: &str) -> Result<[T; N], String> {
    let v: Vec<T> = s
        .split(',')
        .map(|t| {
            t.trim()
                .parse::<T>()
                .map_err(|_| format!("'{}' is not a number", t.trim()))
        })
        .collect::<Result<_, _>>()?;
    let n = v.len();
    v.try_into()
        .map_err(|_| format!("expected {N} comma-separated numbers, got {n}"))
}

pub fn codec(s: &str) -> Result<Codec, String> {
    Codec::parse(s).ok_or_else(|| {
        format!(
            "'{s}': expected lz4, zstd or zstdN (N = 1–19), optionally followed by +delta or +auto"
        )
    })
}

/// `--watchdog` seconds: `None` for 0 (wait forever).
pub fn watchdog(seconds: f64) -> anyhow::Result<Option<std::time::Duration>> {
    anyhow::ensure!(
        seconds.is_finite() && seconds >= 0.0,
        "--watchdog {seconds}: expected seconds ≥ 0 (0: wait forever)"
    );
    Ok((seconds > 0.0).then(|| std::time::Duration::from_secs_f64(seconds)))
}

/// `--hold`: seconds from 0 to a day.
pub fn hold(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if (0.0..=86_400.0).contains(&v) => Ok(v),
        _ => Err("expected seconds from 0 to 86400".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_lists_and_watchdogs() {
        assert_eq!(size::<u32>("160x120"), Ok([160, 120]));
        assert!(size::<u32>("160").is_err());
        assert_eq!(list::<f64, 3>("1, 2,3"), Ok([1.0, 2.0, 3.0]));
        assert!(list::<f64, 3>("1,2").unwrap_err().contains("got 2"));
        assert_eq!(watchdog(0.0).unwrap(), None);
        assert!(watchdog(-1.0).is_err() && watchdog(f64::NAN).is_err());
    }
}
