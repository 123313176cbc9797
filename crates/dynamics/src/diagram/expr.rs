//! Parameter expressions in diagram block fields: `"k"`, `"ta_tb*tb"`, `"-k_x/t_x2"`,
//! `"1/(r_temp*t_r)"`.
//!
//! Grammar (usual precedence, left-associative): `expr = term (('+'|'-') term)*`,
//! `term = unary (('*'|'/') unary)*`, `unary = '-' unary | atom`, `atom = number | name |
//! '(' expr ')'`. Names are the diagram's parameters. An expression is parsed once when the
//! diagram is loaded (names resolved to parameter indices) and evaluated when the block is
//! compiled at initialisation, never in the step loop.

use crate::sens::Scalar;

/// A parsed expression; parameter names resolved to indices.
#[derive(Debug, Clone, PartialEq)]
pub enum Expr {
    Num(f64),
    Param(usize),
    Neg(Box<Expr>),
    Bin(Op, Box<Expr>, Box<Expr>),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Op {
    Add,
    Sub,
    Mul,
    Div,
}

impl Expr {
    /// Value with parameter values `p` (`f64`, or dual numbers carrying the derivatives with
    /// respect to the parameters in a sensitivity pass).
    pub fn eval<S: Scalar>(&self, p: &[S]) -> S {
        match self {
            Expr::Num(v) => S::cst(*v),
            Expr::Param(i) => p[*i],
            Expr::Neg(e) => -e.eval(p),
            Expr::Bin(op, a, b) => {
                let (a, b) = (a.eval(p), b.eval(p));
                match op {
                    Op::Add => a + b,
                    Op::Sub => a - b,
                    Op::Mul => a * b,
                    Op::Div => a / b,
                }
            }
        }
    }

    /// Indices of the parameters the expression reads.
    pub fn params(&self, out: &mut Vec<usize>) {
        match self {
            Expr::Num(_) => {}
            Expr::Param(i) => out.push(*i),
            Expr::Neg(e) => e.params(out),
            Expr::Bin(_, a, b) => {
                a.params(out);
                b.params(out);
            }
        }
    }

    /// Parses `text`; `lookup` resolves a name to a parameter index.
    pub fn parse(text: &str, lookup: &dyn Fn(&str) -> Option<usize>) -> Result<Expr, String> {
        let toks = tokenize(text)?;
        let mut p = Parser {
            toks: &toks,
            pos: 0,
            lookup,
        };
        let e = p.expr()?;
        if p.pos != toks.len() {
            return Err(format!("unexpected '{}' in '{text}'", toks[p.pos].show()));
        }
        Ok(e)
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(f64),
    Name(String),
    Sym(char),
}

impl Tok {
    fn show(&self) -> String {
        match self {
            Tok::Num(v) => v.to_string(),
            Tok::Name(n) => n.clone(),
            Tok::Sym(c) => c.to_string(),
        }
    }
}

fn tokenize(s: &str) -> Result<Vec<Tok>, String> {
    let cs: Vec<char> = s.chars().collect();
    let mut out = vec![];
    let mut i = 0;
    while i < cs.len() {
        let c = cs[i];
        if c.is_whitespace() {
            i += 1;
        } else if "+-*/()".contains(c) {
            out.push(Tok::Sym(c));
            i += 1;
        } else if c.is_ascii_digit() || c == '.' {
            let st = i;
            while i < cs.len()
                && (cs[i].is_ascii_digit()
                    || cs[i] == '.'
                    || cs[i] == 'e'
                    || cs[i] == 'E'
                    || ((cs[i] == '-' || cs[i] == '+') && (cs[i - 1] == 'e' || cs[i - 1] == 'E')))
            {
                i += 1;
            }
            let t: String = cs[st..i].iter().collect();
            let v: f64 = t
                .parse()
                .map_err(|_| format!("bad number '{t}' in '{s}'"))?;
            out.push(Tok::Num(v));
        } else if c.is_alphabetic() || c == '_' {
            let st = i;
            while i < cs.len() && (cs[i].is_alphanumeric() || cs[i] == '_') {
                i += 1;
            }
            out.push(Tok::Name(cs[st..i].iter().collect()));
        } else {
            return Err(format!("unexpected character '{c}' in '{s}'"));
        }
    }
    if out.is_empty() {
        return Err("empty expression".into());
    }
    Ok(out)
}

struct Parser<'a> {
    toks: &'a [Tok],
    pos: usize,
    lookup: &'a dyn Fn(&str) -> Option<usize>,
}

impl Parser<'_> {
    fn peek(&self) -> Option<&Tok> {
        self.toks.get(self.pos)
    }
    fn expr(&mut self) -> Result<Expr, String> {
        let mut a = self.term()?;
        while let Some(Tok::Sym(c @ ('+' | '-'))) = self.peek() {
            let op = if *c == '+' { Op::Add } else { Op::Sub };
            self.pos += 1;
            let b = self.term()?;
            a = Expr::Bin(op, Box::new(a), Box::new(b));
        }
        Ok(a)
    }
    fn term(&mut self) -> Result<Expr, String> {
        let mut a = self.unary()?;
        while let Some(Tok::Sym(c @ ('*' | '/'))) = self.peek() {
            let op = if *c == '*' { Op::Mul } else { Op::Div };
            self.pos += 1;
            let b = self.unary()?;
            a = Expr::Bin(op, Box::new(a), Box::new(b));
        }
        Ok(a)
    }
    fn unary(&mut self) -> Result<Expr, String> {
        if let Some(Tok::Sym('-')) = self.peek() {
            self.pos += 1;
            return Ok(Expr::Neg(Box::new(self.unary()?)));
        }
        self.atom()
    }
    fn atom(&mut self) -> Result<Expr, String> {
        let t = self
            .peek()
            .cloned()
            .ok_or_else(|| "expression ends too early".to_string())?;
        self.pos += 1;
        match t {
            Tok::Num(v) => Ok(Expr::Num(v)),
            Tok::Name(n) => (self.lookup)(&n)
                .map(Expr::Param)
                .ok_or_else(|| format!("unknown parameter '{n}'")),
            Tok::Sym('(') => {
                let e = self.expr()?;
                match self.peek() {
                    Some(Tok::Sym(')')) => {
                        self.pos += 1;
                        Ok(e)
                    }
                    _ => Err("missing ')'".into()),
                }
            }
            Tok::Sym(c) => Err(format!("unexpected '{c}'")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn precedence_names_and_errors() {
        let names = ["a", "b", "c"];
        let look = |n: &str| names.iter().position(|x| *x == n);
        let p = [2.0, 3.0, 4.0];
        let e = |s: &str| Expr::parse(s, &look).unwrap().eval(&p);
        assert_eq!(e("a+b*c"), 14.0);
        assert_eq!(e("(a+b)*c"), 20.0);
        assert_eq!(e("-a/b/c"), -2.0 / 3.0 / 4.0);
        assert_eq!(e("1/(a*c)"), 0.125);
        assert_eq!(e("1.5e-1*c - -a"), 0.6 + 2.0);
        assert!(Expr::parse("a+d", &look).unwrap_err().contains("'d'"));
        assert!(Expr::parse("(a", &look).is_err());
        assert!(Expr::parse("a b", &look).is_err());
        assert!(Expr::parse("", &look).is_err());
        assert!(Expr::parse("a % b", &look).is_err());
    }
}
