//! Block lexer: one line of G-code into words and comments.
//!
//! RS274NGC ignores blanks and tabs outside comments and is case-insensitive,
//! so the line is first folded into a compact upper-case form with a column
//! map back to the original text; nom then parses words from that form.

use nom::{
    branch::alt,
    character::complete::{char, digit0, digit1, one_of, satisfy},
    combinator::{opt, recognize},
    sequence::{pair, tuple},
    IResult,
};

/// One word: a letter and its value, e.g. `G1`, `X-2.5`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Word {
    /// Upper-case letter.
    pub letter: char,
    pub value: f64,
    /// 1-based column of the letter in the original line.
    pub column: u32,
}

/// A comment and the column of its opening `(` or `;`.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Comment {
    pub text: String,
    pub column: u32,
}

/// A lexed block (one line).
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Block {
    /// The line starts with `/` (block delete).
    pub deleted: bool,
    /// The line is a `%` program delimiter.
    pub percent: bool,
    pub words: Vec<Word>,
    pub comments: Vec<Comment>,
}

/// A lexing error at a column.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct LexError {
    pub column: u32,
    pub message: String,
}

/// Lexes lines, reusing its buffers from line to line.
#[derive(Default)]
pub(crate) struct Lexer {
    folded: String,
    columns: Vec<u32>,
}

fn number(input: &str) -> IResult<&str, &str> {
    recognize(tuple((
        opt(one_of("+-")),
        alt((
            recognize(pair(digit1, opt(pair(char('.'), digit0)))),
            recognize(pair(char('.'), digit1)),
        )),
    )))(input)
}

fn letter(input: &str) -> IResult<&str, char> {
    satisfy(|c| c.is_ascii_uppercase())(input)
}

impl Lexer {
    /// Lex `line` into `block` (cleared first).
    pub fn lex(&mut self, line: &str, block: &mut Block) -> Result<(), LexError> {
        block.deleted = false;
        block.percent = false;
        block.words.clear();
        block.comments.clear();
        self.folded.clear();
        self.columns.clear();

        let mut chars = line.char_indices().peekable();
        while let Some((i, c)) = chars.next() {
            let column = line[..i].chars().count() as u32 + 1;
            match c {
                ' ' | '\t' | '\r' => {}
                '(' => {
                    let start = i + 1;
                    let mut end = None;
                    for (j, d) in chars.by_ref() {
                        if d == ')' {
                            end = Some(j);
                            break;
                        }
                        if d == '(' {
                            return Err(LexError {
                                column: line[..j].chars().count() as u32 + 1,
                                message: "nested comment: a comment cannot contain '('".into(),
                            });
                        }
                    }
                    let Some(end) = end else {
                        return Err(LexError {
                            column,
                            message: "unclosed comment: add ')'".into(),
                        });
                    };
                    block.comments.push(Comment {
                        text: line[start..end].to_string(),
                        column,
                    });
                }
                ';' => {
                    block.comments.push(Comment {
                        text: line[i + 1..].to_string(),
                        column,
                    });
                    break;
                }
                c if c.is_ascii() => {
                    self.folded.push(c.to_ascii_uppercase());
                    self.columns.push(column);
                }
                other => {
                    return Err(LexError {
                        column,
                        message: format!("unexpected character {other:?} outside a comment"),
                    })
                }
            }
        }

        let mut rest = self.folded.as_str();
        if let Some(r) = rest.strip_prefix('/') {
            block.deleted = true;
            rest = r;
        }
        if rest == "%" {
            block.percent = true;
            return Ok(());
        }
        while !rest.is_empty() {
            let offset = self.folded.len() - rest.len();
            let column = self.columns[offset];
            let (after, letter) = letter(rest).map_err(|_| LexError {
                column,
                message: format!(
                    "expected a word letter, found {:?}",
                    rest.chars().next().unwrap_or(' ')
                ),
            })?;
            if after.starts_with('#') || after.starts_with('[') {
                return Err(LexError {
                    column,
                    message: "parameters and expressions are not supported yet".into(),
                });
            }
            let (after, text) = number(after).map_err(|_| LexError {
                column,
                message: format!("{letter}: expected a number after the letter"),
            })?;
            let value: f64 = text.parse().map_err(|_| LexError {
                column,
                message: format!("{letter}: bad number {text:?}"),
            })?;
            block.words.push(Word {
                letter,
                value,
                column,
            });
            rest = after;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lex(line: &str) -> Result<Block, LexError> {
        let mut block = Block::default();
        Lexer::default().lex(line, &mut block).map(|_| block)
    }

    #[test]
    fn spaces_inside_words_and_numbers_are_ignored() {
        let b = lex("g 0 1 x 1 0 . 5 y-.25").unwrap();
        let got: Vec<(char, f64)> = b.words.iter().map(|w| (w.letter, w.value)).collect();
        assert_eq!(got, vec![('G', 1.0), ('X', 10.5), ('Y', -0.25)]);
        assert_eq!(b.words[1].column, 7);
    }

    #[test]
    fn comments_are_kept_with_their_column() {
        let b = lex("G1 (move) X1 ; rest").unwrap();
        assert_eq!(b.words.len(), 2);
        assert_eq!(b.comments[0].text, "move");
        assert_eq!(b.comments[0].column, 4);
        assert_eq!(b.comments[1].text, " rest");
    }

    #[test]
    fn block_delete_and_percent() {
        assert!(lex("/G0 X1").unwrap().deleted);
        assert!(lex(" % ").unwrap().percent);
    }

    #[test]
    fn errors_name_the_column() {
        let e = lex("G1 X").unwrap_err();
        assert_eq!(e.column, 4);
        let e = lex("G1 (open").unwrap_err();
        assert_eq!(e.column, 4);
        let e = lex("G1 X#1").unwrap_err();
        assert!(e.message.contains("not supported"), "{}", e.message);
        let e = lex("G1 ?").unwrap_err();
        assert_eq!(e.column, 4);
    }
}
