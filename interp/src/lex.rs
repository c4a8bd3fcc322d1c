//! Token recognisers for a folded line (lower case, blanks removed outside
//! comments), written with nom.
//!
//! The reader in `read.rs` walks the line word by word as LinuxCNC's does,
//! because values are evaluated as they are read and errors must name the
//! column where LinuxCNC's reader stops. What it needs at each step is a
//! small token: a number, an operator, a function name, an O-word keyword,
//! a `<name>`. Those are recognised here; each parser takes the rest of the
//! line and returns the rest after the token, so the reader advances its
//! index by the difference. On failure the reader reports LinuxCNC's error
//! message for the position.

use nom::branch::alt;
use nom::bytes::complete::{tag, take_until, take_while, take_while1};
use nom::character::complete::char;
use nom::combinator::{opt, recognize, value};
use nom::sequence::{delimited, pair, preceded};
use nom::IResult;

use crate::block::OType;

/// Binary operators of expressions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Op {
    /// `]`: the end of the bracketed expression (lowest precedence).
    RightBracket,
    DividedBy,
    Modulo,
    Power,
    Times,
    And,
    Xor,
    Minus,
    Or,
    Plus,
    Lt,
    Eq,
    Ne,
    Le,
    Ge,
    Gt,
}

/// Unary functions (`ATAN` takes two bracketed arguments).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Func {
    Abs,
    Acos,
    Asin,
    Atan,
    Cos,
    Exp,
    Exists,
    Fix,
    Fup,
    Ln,
    Round,
    Sin,
    Sqrt,
    Tan,
}

type Res<'a, T> = IResult<&'a [u8], T>;

fn digits0(i: &[u8]) -> Res<'_, &[u8]> {
    take_while(|c: u8| c.is_ascii_digit())(i)
}

fn digits1(i: &[u8]) -> Res<'_, &[u8]> {
    take_while1(|c: u8| c.is_ascii_digit())(i)
}

/// An unsigned decimal: digits with at most one point and at least one
/// digit (`12`, `12.`, `.5`, `1.25`).
pub(crate) fn unsigned_decimal(i: &[u8]) -> Res<'_, &[u8]> {
    alt((
        recognize(pair(digits1, opt(pair(char('.'), digits0)))),
        recognize(pair(char('.'), digits1)),
    ))(i)
}

/// A run of sign characters and then of digits and points: the span
/// LinuxCNC's number reader hands to its converter (which may reject it).
pub(crate) fn number_span(i: &[u8]) -> Res<'_, &[u8]> {
    recognize(pair(
        take_while(|c| c == b'+' || c == b'-'),
        take_while(|c: u8| c.is_ascii_digit() || c == b'.'),
    ))(i)
}

/// An optional sign and an unsigned decimal; returns whether the sign was
/// minus and the digits.
pub(crate) fn signed_decimal(i: &[u8]) -> Res<'_, (bool, &[u8])> {
    let (i, sign) = opt(alt((char('+'), char('-'))))(i)?;
    let (i, body) = unsigned_decimal(i)?;
    Ok((i, (sign == Some('-'), body)))
}

/// Digits only (N words, parameter numbers of the O-word forms).
pub(crate) fn unsigned_integer(i: &[u8]) -> Res<'_, &[u8]> {
    digits1(i)
}

/// A binary operator or the closing bracket.
pub(crate) fn operation(i: &[u8]) -> Res<'_, Op> {
    alt((
        alt((
            value(Op::RightBracket, char(']')),
            value(Op::Plus, char('+')),
            value(Op::Minus, char('-')),
            value(Op::Power, tag("**")),
            value(Op::Times, char('*')),
            value(Op::DividedBy, char('/')),
        )),
        alt((
            value(Op::And, tag("and")),
            value(Op::Modulo, tag("mod")),
            value(Op::Xor, tag("xor")),
            value(Op::Or, tag("or")),
            value(Op::Eq, tag("eq")),
            value(Op::Ne, tag("ne")),
            value(Op::Ge, tag("ge")),
            value(Op::Gt, tag("gt")),
            value(Op::Le, tag("le")),
            value(Op::Lt, tag("lt")),
        )),
    ))(i)
}

/// A function name (without its bracket).
pub(crate) fn function(i: &[u8]) -> Res<'_, Func> {
    alt((
        alt((
            value(Func::Abs, tag("abs")),
            value(Func::Acos, tag("acos")),
            value(Func::Asin, tag("asin")),
            value(Func::Atan, tag("atan")),
            value(Func::Cos, tag("cos")),
            value(Func::Exp, tag("exp")),
            value(Func::Exists, tag("exists")),
        )),
        alt((
            value(Func::Fix, tag("fix")),
            value(Func::Fup, tag("fup")),
            value(Func::Ln, tag("ln")),
            value(Func::Round, tag("round")),
            value(Func::Sin, tag("sin")),
            value(Func::Sqrt, tag("sqrt")),
            value(Func::Tan, tag("tan")),
        )),
    ))(i)
}

/// The keyword after an O-word's number or name. Longer keywords that
/// share a start with shorter ones come first (`elseif` before `else`).
pub(crate) fn o_keyword(i: &[u8]) -> Res<'_, OType> {
    alt((
        alt((
            value(OType::EndSub, tag("endsub")),
            value(OType::EndWhile, tag("endwhile")),
            value(OType::EndRepeat, tag("endrepeat")),
            value(OType::EndIf, tag("endif")),
            value(OType::Sub, tag("sub")),
            value(OType::Call, tag("call")),
            value(OType::Do, tag("do")),
            value(OType::While, tag("while")),
        )),
        alt((
            value(OType::Repeat, tag("repeat")),
            value(OType::If, tag("if")),
            value(OType::ElseIf, tag("elseif")),
            value(OType::Else, tag("else")),
            value(OType::Break, tag("break")),
            value(OType::Continue, tag("continue")),
            value(OType::Return, tag("return")),
        )),
    ))(i)
}

/// `<name>`: returns the text between the angle brackets.
pub(crate) fn bracketed_name(i: &[u8]) -> Res<'_, &[u8]> {
    delimited(char('<'), take_until(">"), char('>'))(i)
}

/// A comment `( … )`: returns the text between the parentheses.
pub(crate) fn comment(i: &[u8]) -> Res<'_, &[u8]> {
    preceded(char('('), take_until(")"))(i).map(|(rest, body)| (&rest[1..], body))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimals() {
        assert_eq!(unsigned_decimal(b"12.5x"), Ok((&b"x"[..], &b"12.5"[..])));
        assert_eq!(unsigned_decimal(b"12."), Ok((&b""[..], &b"12."[..])));
        assert_eq!(unsigned_decimal(b".5]"), Ok((&b"]"[..], &b".5"[..])));
        assert!(unsigned_decimal(b".x").is_err());
        assert!(unsigned_decimal(b"-1").is_err());
        assert_eq!(
            signed_decimal(b"-0.25"),
            Ok((&b""[..], (true, &b"0.25"[..])))
        );
        assert_eq!(number_span(b"+-1.2.3y"), Ok((&b"y"[..], &b"+-1.2.3"[..])));
    }

    #[test]
    fn operators_take_the_longest_match() {
        assert_eq!(operation(b"**2"), Ok((&b"2"[..], Op::Power)));
        assert_eq!(operation(b"*2"), Ok((&b"2"[..], Op::Times)));
        assert_eq!(operation(b"ge1"), Ok((&b"1"[..], Op::Ge)));
        assert_eq!(operation(b"mod3"), Ok((&b"3"[..], Op::Modulo)));
        assert!(operation(b"an").is_err());
    }

    #[test]
    fn keywords_and_names() {
        assert_eq!(o_keyword(b"elseif[1]"), Ok((&b"[1]"[..], OType::ElseIf)));
        assert_eq!(o_keyword(b"else"), Ok((&b""[..], OType::Else)));
        assert_eq!(o_keyword(b"endwhile"), Ok((&b""[..], OType::EndWhile)));
        assert_eq!(
            function(b"exists[#<a>]"),
            Ok((&b"[#<a>]"[..], Func::Exists))
        );
        assert_eq!(function(b"exp[1]"), Ok((&b"[1]"[..], Func::Exp)));
        assert_eq!(
            bracketed_name(b"<my_var>=1"),
            Ok((&b"=1"[..], &b"my_var"[..]))
        );
        assert!(bracketed_name(b"<open").is_err());
        assert_eq!(comment(b"(hi)x"), Ok((&b"x"[..], &b"hi"[..])));
    }
}
