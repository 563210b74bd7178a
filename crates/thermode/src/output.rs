//! Writing files the CLI produces through the one atomic writer (`thermode_platform::write_atomically`: temporary
//! file beside the target, synced, renamed, folder synced; a device or FIFO is written in place), so that an error
//! never leaves half a file behind, and printing to standard output without panicking on a closed pipe.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use anyhow::{Context, Result};
use thermode_platform::WriteError;

/// Writes the bytes produced by `fill` to `path` atomically; errors name `path`.
pub fn write_atomically(path: &Path, fill: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
    let fill_file = |tmp: &Path| -> Result<()> {
        let file = File::options().write(true).create(true).truncate(true).open(tmp)?;
        let mut writer = BufWriter::new(file);
        fill(&mut writer)?;
        writer.flush()?;
        Ok(())
    };
    thermode_platform::write_atomically(path, fill_file)
        .map_err(|e| match e {
            WriteError::Fill(e) => e,
            WriteError::Io { source, .. } => source.into(),
        })
        .with_context(|| format!("cannot write {}", path.display()))
}
/// Prints `text` to standard output; a closed pipe (e.g. `| head`) ends quietly instead of panicking.
pub fn print_stdout(text: &str) -> Result<()> {
    let mut stdout = std::io::stdout().lock();
    match stdout.write_all(text.as_bytes()).and_then(|()| stdout.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        Err(e) => Err(e).context("cannot write to standard output"),
    }
}
