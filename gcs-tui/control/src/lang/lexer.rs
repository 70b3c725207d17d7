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

/// `word` as the lexer reads it back as one word, literally: unchanged when
/// it is a plain word, in quotes (escaped) when it is empty or has spaces,
/// quotes or `#` in it. A program composing command lines from names (the
/// TUI, a client) quotes each name with it. A plain word that is also a
/// keyword (`none`, `all`) stays plain: write `"none"` to mean a name.
pub fn quote(word: &str) -> std::borrow::Cow<'_, str> {
    let plain = !word.is_empty()
        && !word
            .chars()
            .any(|c| c.is_whitespace() || c.is_control() || c == '"' || c == '#');
    if plain {
        return word.into();
    }
    let mut q = String::with_capacity(word.len() + 2);
    q.push('"');
    for c in word.chars() {
        match c {
            '"' => q.push_str("\\\""),
            '\\' => q.push_str("\\\\"),
            '\n' => q.push_str("\\n"),
            c => q.push(c),
        }
    }
    q.push('"');
    q.into()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quoted_words_read_back_as_themselves() {
        for w in [
            "robot_1",
            "a b",
            "",
            "#x",
            "say \"hi\"",
            "back\\slash",
            "two\nlines",
            "none",
        ] {
            let line = format!("log {}", quote(w));
            let words = &lex(&line, 1).unwrap()[0].words;
            assert_eq!(words.len(), 2, "{line}");
            assert_eq!(words[1].text, w, "{line}");
        }
        assert_eq!(quote("joy/0"), "joy/0");
        assert_eq!(quote("none"), "none", "keywords are the caller's choice");
    }

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
