//! The experimenter's terminal: plain line-based messages and prompts (works in any terminal and in tmux).

use std::io::{BufRead, Write};

/// Where the runner talks to the experimenter.
pub trait Console {
    /// Shows one line.
    fn say(&mut self, line: &str) -> std::io::Result<()>;
    /// Shows `prompt` and reads one line (without its line end); `None` when the input has ended.
    fn ask(&mut self, prompt: &str) -> std::io::Result<Option<String>>;
}

/// A console over any reader and writer (standard input and output in the CLI).
#[derive(Debug)]
pub struct TerminalConsole<R, W> {
    input: R,
    output: W,
}

impl<R: BufRead, W: Write> TerminalConsole<R, W> {
    /// A console reading lines from `input` and writing to `output`.
    pub fn new(input: R, output: W) -> Self {
        TerminalConsole { input, output }
    }

    /// The output (e.g. a buffer in tests).
    pub fn into_output(self) -> W {
        self.output
    }
}

impl<R: BufRead, W: Write> Console for TerminalConsole<R, W> {
    fn say(&mut self, line: &str) -> std::io::Result<()> {
        writeln!(self.output, "{line}")?;
        self.output.flush()
    }

    fn ask(&mut self, prompt: &str) -> std::io::Result<Option<String>> {
        write!(self.output, "{prompt}")?;
        self.output.flush()?;
        let mut line = String::new();
        if self.input.read_line(&mut line)? == 0 {
            return Ok(None);
        }
        Ok(Some(line.trim_end_matches(['\n', '\r']).to_string()))
    }
}

/// A console that shows nothing and has no input (scripted runs in tests).
#[derive(Debug, Default, Clone, Copy)]
pub struct QuietConsole;

impl Console for QuietConsole {
    fn say(&mut self, _line: &str) -> std::io::Result<()> {
        Ok(())
    }

    fn ask(&mut self, _prompt: &str) -> std::io::Result<Option<String>> {
        Ok(None)
    }
}
