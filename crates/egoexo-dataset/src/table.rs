//! Markdown tables of evaluation results: each column's header, alignment and cell written in
//! one place, so a header cannot drift from the value under it.

/// How a column's cells align (the `|---|` / `|---:|` of its separator).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Align {
    Left,
    Right,
}

/// A column of a table over rows `R`: its header, alignment and the text of its cell.
pub(crate) type Column<R> = (&'static str, Align, fn(&R) -> String);

/// The header, the separator and one line per row, each ending in a newline.
pub(crate) fn markdown_table<R>(columns: &[Column<R>], rows: &[R]) -> String {
    let line = |cells: Vec<String>| format!("| {} |\n", cells.join(" | "));
    let mut out = line(columns.iter().map(|(header, _, _)| header.to_string()).collect());
    out += &format!(
        "|{}|\n",
        columns
            .iter()
            .map(|(_, align, _)| if *align == Align::Right { "---:" } else { "---" })
            .collect::<Vec<_>>()
            .join("|")
    );
    for row in rows {
        out += &line(columns.iter().map(|(_, _, cell)| cell(row)).collect());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_separator_and_rows() {
        let columns: [Column<(u32, f64)>; 2] =
            [("n", Align::Left, |r| r.0.to_string()), ("x (cm)", Align::Right, |r| format!("{:.2}", r.1))];
        assert_eq!(
            markdown_table(&columns, &[(1, 2.0), (3, 0.125)]),
            "| n | x (cm) |\n|---|---:|\n| 1 | 2.00 |\n| 3 | 0.12 |\n"
        );
    }
}
