//! Renders report [`Block`]s as Markdown (GitHub tables, `**bold**`, `*italic*`) and as a self-contained HTML page
//! (inline style sheet; figures as `<img>` of the SVG with the PNG as fallback and link).

use super::blocks::{Block, Cell, Emphasis, Table};

/// The report as Markdown.
pub fn markdown(blocks: &[Block]) -> String {
    let mut out = String::new();
    for block in blocks {
        match block {
            Block::Heading(level, text) => {
                out.push_str(&format!("{} {}\n\n", "#".repeat(usize::from(*level)), md_escape(text)));
            }
            Block::Paragraph(text) => out.push_str(&format!("{}\n\n", md_escape(text))),
            Block::Table(table) => out.push_str(&md_table(table)),
            Block::Figure { stem, caption } => out.push_str(&format!(
                "![{caption}]({stem}.svg)\n\n{} (PNG: [{stem}.png]({stem}.png))\n\n",
                md_escape(caption),
                caption = md_escape(caption)
            )),
        }
    }
    out
}

fn md_table(table: &Table) -> String {
    let mut out = format!("{}\n\n", md_escape(&table.caption));
    let header: Vec<String> = table.header.iter().map(|h| md_escape(h)).collect();
    out.push_str(&format!("| {} |\n", header.join(" | ")));
    out.push_str(&format!("|{}\n", " --- |".repeat(header.len())));
    for row in &table.rows {
        let cells: Vec<String> = row.iter().map(md_cell).collect();
        out.push_str(&format!("| {} |\n", cells.join(" | ")));
    }
    out.push('\n');
    out
}

fn md_cell(cell: &Cell) -> String {
    let text = md_escape(&cell.text);
    match cell.emphasis {
        Emphasis::None => text,
        Emphasis::Bold => format!("**{text}**"),
        Emphasis::Italic => format!("*{text}*"),
    }
}

/// Escapes the characters that Markdown would read as markup (`\`, `*`, `_`, `|`, `` ` ``, `[`, `]`, `<`, `>`).
fn md_escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        if matches!(c, '\\' | '*' | '_' | '|' | '`' | '[' | ']' | '<' | '>') {
            out.push('\\');
        }
        out.push(c);
    }
    out
}

const STYLE: &str = "body{font-family:sans-serif;max-width:60em;margin:2em auto;padding:0 1em;color:#222}\
table{border-collapse:collapse;margin:0.5em 0 1.5em}th,td{border:1px solid #bbb;padding:0.25em 0.6em;\
text-align:right}th:first-child,td:first-child{text-align:left}caption{caption-side:top;text-align:left;\
padding:0.3em 0;font-style:normal;color:#444}figure{margin:1em 0}img{max-width:100%}";

/// The report as a self-contained HTML page.
pub fn html(blocks: &[Block]) -> String {
    let title = blocks
        .iter()
        .find_map(|b| match b {
            Block::Heading(_, text) => Some(text.as_str()),
            _ => None,
        })
        .unwrap_or("thermode lab report");
    let mut out = format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n<style>{STYLE}</style>\n\
         </head>\n<body>\n",
        html_escape(title)
    );
    for block in blocks {
        match block {
            Block::Heading(level, text) => out.push_str(&format!("<h{level}>{}</h{level}>\n", html_escape(text))),
            Block::Paragraph(text) => out.push_str(&format!("<p>{}</p>\n", html_escape(text))),
            Block::Table(table) => out.push_str(&html_table(table)),
            Block::Figure { stem, caption } => {
                let caption = html_escape(caption);
                out.push_str(&format!(
                    "<figure>\n<picture><source srcset=\"{stem}.svg\" type=\"image/svg+xml\">\
                     <img src=\"{stem}.png\" alt=\"{caption}\"></picture>\n\
                     <figcaption>{caption} (<a href=\"{stem}.svg\">SVG</a>, <a href=\"{stem}.png\">PNG</a>)\
                     </figcaption>\n</figure>\n"
                ));
            }
        }
    }
    out.push_str("</body>\n</html>\n");
    out
}

fn html_table(table: &Table) -> String {
    let mut out = format!(
        "<table>\n<caption>{}</caption>\n<thead><tr>",
        html_escape(&table.caption)
    );
    for heading in &table.header {
        out.push_str(&format!("<th>{}</th>", html_escape(heading)));
    }
    out.push_str("</tr></thead>\n<tbody>\n");
    for row in &table.rows {
        out.push_str("<tr>");
        for cell in row {
            let text = html_escape(&cell.text);
            let inner = match cell.emphasis {
                Emphasis::None => text,
                Emphasis::Bold => format!("<b>{text}</b>"),
                Emphasis::Italic => format!("<i>{text}</i>"),
            };
            out.push_str(&format!("<td>{inner}</td>"));
        }
        out.push_str("</tr>\n");
    }
    out.push_str("</tbody>\n</table>\n");
    out
}

/// Escapes `&`, `<`, `>` and `"`.
fn html_escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Vec<Block> {
        vec![
            Block::Heading(1, "T <1>".to_string()),
            Block::Table(Table {
                caption: "c".to_string(),
                header: vec!["a".to_string(), "b".to_string()],
                rows: vec![vec![
                    Cell {
                        text: "1.01".to_string(),
                        emphasis: Emphasis::Bold,
                    },
                    Cell {
                        text: "stainless_steel".to_string(),
                        emphasis: Emphasis::Italic,
                    },
                ]],
            }),
        ]
    }

    #[test]
    fn markdown_marks_bold_and_italic_and_escapes() {
        let text = markdown(&sample());
        assert!(text.contains("| **1.01** | *stainless\\_steel* |"), "{text}");
        assert!(text.contains("# T \\<1\\>"), "{text}");
    }

    #[test]
    fn html_marks_bold_and_italic_and_escapes() {
        let text = html(&sample());
        assert!(
            text.contains("<td><b>1.01</b></td><td><i>stainless_steel</i></td>"),
            "{text}"
        );
        assert!(text.contains("<title>T &lt;1&gt;</title>"), "{text}");
    }
}
