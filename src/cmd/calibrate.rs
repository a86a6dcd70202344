//! `parallax calibrate mpcdi`: a VESA MPCDI calibration into projector
//! files (backend/src/mpcdi.rs).

use anyhow::Result;
use clap::Subcommand;
use std::path::PathBuf;

/// Projector calibration: import a VESA MPCDI file's warps and blend maps.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    format: Format,
}

#[derive(Subcommand)]
enum Format {
    /// Each region of a 2d-profile .mpcdi file becomes the [calibration]
    /// of the projector file named by its id, in PROJECTORS (its warp and
    /// blend map are written beside it).
    Mpcdi {
        input: PathBuf,
        #[arg(long)]
        projectors: PathBuf,
    },
}

pub fn run(a: Args) -> Result<()> {
    match a.format {
        Format::Mpcdi { input, projectors } => {
            let ids = parallax_backend::mpcdi::import(&input, &projectors)?;
            println!(
                "calibrated {} projector(s) in {}: {}",
                ids.len(),
                projectors.display(),
                ids.join(", ")
            );
            Ok(())
        }
    }
}
