//! Writing results: Markdown reports and CSV tables.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context as _, Result};

/// A Markdown document being written.
#[derive(Debug, Default)]
pub struct Markdown {
    text: String,
}

impl Markdown {
    pub fn new(title: &str) -> Markdown {
        let mut md = Markdown::default();
        let _ = writeln!(md.text, "# {title}\n");
        md
    }

    pub fn heading(&mut self, text: &str) {
        let _ = writeln!(self.text, "## {text}\n");
    }

    pub fn subheading(&mut self, text: &str) {
        let _ = writeln!(self.text, "### {text}\n");
    }

    pub fn paragraph(&mut self, text: &str) {
        let _ = writeln!(self.text, "{}\n", text.trim_end());
    }

    pub fn bullets<S: AsRef<str>>(&mut self, items: &[S]) {
        for item in items {
            let _ = writeln!(self.text, "- {}", item.as_ref());
        }
        self.text.push('\n');
    }

    pub fn table<S: AsRef<str>>(&mut self, headers: &[&str], rows: &[Vec<S>]) {
        let _ = writeln!(self.text, "| {} |", headers.join(" | "));
        let _ = writeln!(
            self.text,
            "|{}|",
            headers.iter().map(|_| "---").collect::<Vec<_>>().join("|")
        );
        for row in rows {
            let cells: Vec<String> = row.iter().map(|c| c.as_ref().replace('|', "\\|")).collect();
            let _ = writeln!(self.text, "| {} |", cells.join(" | "));
        }
        self.text.push('\n');
    }

    pub fn image(&mut self, alt: &str, file: &str) {
        let _ = writeln!(self.text, "![{alt}]({file})\n");
    }

    pub fn code(&mut self, language: &str, text: &str) {
        let _ = writeln!(self.text, "```{language}\n{}\n```\n", text.trim_end());
    }

    pub fn as_str(&self) -> &str {
        &self.text
    }

    pub fn write(&self, path: &Path) -> Result<()> {
        std::fs::write(path, &self.text).with_context(|| format!("writing {}", path.display()))
    }
}

/// One CSV field: quoted when it holds a separator, a quote or a line break.
pub fn csv_field(value: &str) -> String {
    if value.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", value.replace('"', "\"\""))
    } else {
        value.to_owned()
    }
}

/// A float for CSV: full precision, empty for NaN.
pub fn num(value: f64) -> String {
    if value.is_finite() { format!("{value}") } else { String::new() }
}

pub fn write_csv(path: &Path, headers: &[&str], rows: &[Vec<String>]) -> Result<()> {
    let mut text = headers.iter().map(|h| csv_field(h)).collect::<Vec<_>>().join(",");
    text.push('\n');
    for row in rows {
        text.push_str(&row.iter().map(|c| csv_field(c)).collect::<Vec<_>>().join(","));
        text.push('\n');
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// "45.2%" or "n/a".
pub fn pct(value: f64) -> String {
    if value.is_finite() { format!("{:.1}%", 100.0 * value) } else { "n/a".to_owned() }
}

/// "yes" / "**no**": a missed target stands out in the report.
pub fn verdict(met: bool) -> String {
    if met { "yes".to_owned() } else { "**no**".to_owned() }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_quotes_only_what_needs_it() {
        assert_eq!(csv_field("plain"), "plain");
        assert_eq!(csv_field("a,b"), "\"a,b\"");
        assert_eq!(csv_field("say \"hi\""), "\"say \"\"hi\"\"\"");
        assert_eq!(num(f64::NAN), "");
        assert_eq!(num(0.5), "0.5");
    }

    #[test]
    fn markdown_tables_escape_pipes() {
        let mut md = Markdown::new("t");
        md.table(&["a", "b"], &[vec!["1", "x|y"]]);
        assert!(md.as_str().contains("| 1 | x\\|y |"), "{}", md.as_str());
        assert!(md.as_str().contains("|---|---|"));
    }
}
