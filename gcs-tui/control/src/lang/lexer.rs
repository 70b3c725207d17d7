//! Splits a script into words, each with its line and column; handles
//! comments (`#` to end of line) and quoted text (`"..."` with `\"`, `\\`,
//! `\n` escapes).

use super::{LangError, Span};

/// One word of a command line.
#[derive(Debug, Clone, PartialEq)]
pub struct Word {
    pub text: String,
    pub span: Span,
    /// Written in quotes (so never a keyword).
    pub quoted: bool,
}

/// The words of one line, with the line's text for messages.
#[derive(Debug, Clone, PartialEq)]
pub struct Line {
    pub number: usize,
    pub text: String,
    pub words: Vec<Word>,
}

/// Splits `source` into its non-empty lines. `first_line` numbers the first
/// line (1 for a file; the TUI uses 1 for its single line).
pub fn lex(source: &str, first_line: usize) -> Result<Vec<Line>, LangError> {
    let mut lines = Vec::new();
    for (i, text) in source.lines().enumerate() {
        let number = first_line + i;
        let words = lex_line(text, number)?;
        if !words.is_empty() {
            lines.push(Line {
                number,
                text: text.trim().to_string(),
                words,
            });
        }
    }
    Ok(lines)
}

fn lex_line(text: &str, line: usize) -> Result<Vec<Word>, LangError> {
    let mut words = Vec::new();
    let mut chars = text.char_indices().peekable();
    let col = |byte: usize| text[..byte].chars().count() + 1;
    while let Some(&(start, c)) = chars.peek() {
        if c.is_whitespace() {
            chars.next();
            continue;
        }
        if c == '#' {
            break;
        }
        let span = Span {
            line,
            column: col(start),
        };
        if c == '"' {
            chars.next();
            let mut s = String::new();
            let mut closed = false;
            while let Some((_, c)) = chars.next() {
                match c {
                    '"' => {
                        closed = true;
                        break;
                    }
                    '\\' => match chars.next() {
                        Some((_, 'n')) => s.push('\n'),
                        Some((_, '"')) => s.push('"'),
                        Some((_, '\\')) => s.push('\\'),
                        Some((at, other)) => {
                            return Err(LangError::new(
                                Span {
                                    line,
                                    column: col(at),
                                },
                                format!("unknown escape \\{other} (use \\\", \\\\ or \\n)"),
                            ));
                        }
                        None => break,
                    },
                    c => s.push(c),
                }
            }
            if !closed {
                return Err(LangError::new(span, "unterminated quoted text"));
            }
            words.push(Word {
                text: s,
                span,
                quoted: true,
            });
        } else {
            let mut end = start;
            while let Some(&(at, c)) = chars.peek() {
                if c.is_whitespace() || c == '"' || c == '#' {
                    break;
                }
                end = at + c.len_utf8();
                chars.next();
            }
            words.push(Word {
                text: text[start..end].to_string(),
                span,
                quoted: false,
            });
        }
    }
    Ok(words)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_comments_quotes_and_columns() {
        let lines = lex(
            "\n  route robot_1 joy/0  # to the pad\nlog \"a \\\"b\\\" c\"\n",
            1,
        )
        .unwrap();
        assert_eq!(lines.len(), 2);
        assert_eq!(lines[0].number, 2);
        let w: Vec<_> = lines[0]
            .words
            .iter()
            .map(|w| (w.text.as_str(), w.span.column))
            .collect();
        assert_eq!(w, vec![("route", 3), ("robot_1", 9), ("joy/0", 17)]);
        assert_eq!(lines[1].words[1].text, "a \"b\" c");
        assert!(lines[1].words[1].quoted);
    }

    #[test]
    fn unterminated_quote_points_at_it() {
        let e = lex("log ok\nlog \"oops", 1).unwrap_err();
        assert_eq!(e.span, Span { line: 2, column: 5 });
    }
}
