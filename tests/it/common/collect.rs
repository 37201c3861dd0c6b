//! A sink that keeps everything a post writes: the NC text, each block, every diagnostic.

use kinepost::diag::{Code, Diagnostic};
use kinepost::post::{BlockInfo, Sink};

#[derive(Default)]
pub struct Collect {
    pub nc: String,
    pub blocks: Vec<BlockInfo>,
    /// Each motion block's text.
    pub texts: Vec<String>,
    pub diags: Vec<Diagnostic>,
}

impl Sink for Collect {
    fn line(&mut self, text: &str, b: Option<&BlockInfo>) -> Result<(), kinepost::post::Stop> {
        self.nc.push_str(text);
        self.nc.push('\n');
        if let Some(b) = b {
            self.diags.extend(b.diagnostics.iter().cloned());
            self.blocks.push(b.clone());
            self.texts.push(text.to_string());
        }
        Ok(())
    }
    fn diagnostic(&mut self, d: &Diagnostic) -> Result<(), kinepost::post::Stop> {
        self.diags.push(d.clone());
        Ok(())
    }
}

impl Collect {
    /// The CL lines of the motion blocks that carry `word`.
    pub fn lines_with(&self, word: &str) -> Vec<u32> {
        self.blocks
            .iter()
            .zip(&self.texts)
            .filter(|(_, t)| t.split_whitespace().any(|w| w == word))
            .filter_map(|(b, _)| b.source_line)
            .collect()
    }

    /// The first diagnostic with `code` (the test fails without one).
    pub fn first(&self, code: Code) -> &Diagnostic {
        self.diags
            .iter()
            .find(|d| d.code == code)
            .unwrap_or_else(|| panic!("no {} diagnostic: {:?}", code.as_str(), self.diags))
    }

    /// The one diagnostic with `code` (the test fails on none or several).
    pub fn only(&self, code: Code) -> &Diagnostic {
        let all: Vec<_> = self.diags.iter().filter(|d| d.code == code).collect();
        assert_eq!(all.len(), 1, "one {} diagnostic: {all:?}", code.as_str());
        all[0]
    }
}
