//! `parallax info`: what a database holds; `--verify` checks every brick.

use anyhow::Result;
use parallax_backend::store::{info, OctreeDb};
use std::path::PathBuf;

/// Describe a database; --verify decodes and checks every brick.
#[derive(clap::Args)]
pub struct Args {
    database: PathBuf,
    #[arg(long)]
    verify: bool,
}

pub fn run(a: Args) -> Result<()> {
    let db = OctreeDb::open(&a.database)?;
    print!("{}", info::describe(&db));
    if a.verify {
        let r = info::verify(&db)?;
        println!(
            "verify:        ok, {} bricks ({} bytes) decoded and checked",
            r.bricks, r.bytes
        );
    }
    Ok(())
}
