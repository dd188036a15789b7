//! A report's summary for a person: a title line, then one `label  value` line per figure with the values
//! aligned.

use std::fmt;

/// A title and labelled lines, printed with the values in one column.
#[derive(Clone, Debug, Default)]
pub struct Summary {
    title: String,
    rows: Vec<(String, String)>,
}

impl Summary {
    /// A summary headed by `title` (what ran).
    pub fn new(title: impl Into<String>) -> Self {
        Summary { title: title.into(), rows: Vec::new() }
    }

    /// Adds the line `label  value`.
    pub fn row(&mut self, label: impl Into<String>, value: impl fmt::Display) -> &mut Self {
        self.rows.push((label.into(), value.to_string()));
        self
    }
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "{}", self.title)?;
        let width = self.rows.iter().map(|(l, _)| l.chars().count()).max().unwrap_or(0);
        for (label, value) in &self.rows {
            writeln!(f, "  {label:<width$}  {value}")?;
        }
        Ok(())
    }
}

/// `yes` or `no`.
pub fn yes_no(b: bool) -> &'static str {
    if b {
        "yes"
    } else {
        "no"
    }
}

/// A value that may be missing (NaN): `value` formatted with `decimals`, or `n/a`.
pub fn or_na(value: f64, decimals: usize) -> String {
    if value.is_finite() {
        format!("{value:.decimals$}")
    } else {
        "n/a".into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_line_up_after_the_longest_label() {
        let mut s = Summary::new("run");
        s.row("a", 1).row("longer", "x");
        assert_eq!(s.to_string(), "run\n  a       1\n  longer  x\n");
    }
}
