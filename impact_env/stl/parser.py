"""Parse STL text into the syntax tree of :mod:`impact_env.stl.formula`, without eval.

A hand-written tokenizer and recursive-descent parser. Grammar, loosest binding first::

    formula := conj ('|' conj)*
    conj    := until ('&' until)*
    until   := unary ('U' interval unary)?          # non-associative: a U b U c needs parentheses
    unary   := '!' unary | 'F' interval unary | 'G' interval unary | atom
    atom    := 'in' '(' NAME ',' NAME ')' | 'true' | 'false' | '(' formula ')'
    interval:= '[' NUMBER ',' NUMBER ']'            # seconds, 0 <= a <= b

so ``F[0,100] in(O1, goal) & G[0,100] !in(R1, W1)`` is ``And(F(...), G(Not(...)))``. A chain ``a & b & c``
becomes one n-ary And; a parenthesised group stays a separate node, which is what makes ``parse(str(f)) == f``
hold for every tree. Names, numbers, errors and the limit on nesting: see :func:`parse`.
"""

from __future__ import annotations

import math
import re
from typing import NamedTuple

from impact_env.errors import STLSyntaxError
from impact_env.stl.formula import (
    Always,
    And,
    Eventually,
    FalseFormula,
    Formula,
    InRegion,
    Not,
    Or,
    TrueFormula,
    Until,
)

MAX_NESTING = 100
# one token after optional white space: a number, a name, one punctuation character, any other character
# (an error) or the end of the text. Every position is the start of a match, so finditer never rescans: a
# pattern that could fail would make finditer retry at each following position, which is quadratic in a run
# of spaces before the failure (20,000 trailing spaces took 87 s)
_TOKEN = re.compile(r"\s*(?:(?P<number>(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?)"
                    r"|(?P<name>[A-Za-z_][A-Za-z0-9_]*)|(?P<punct>[()\[\],!&|])|(?P<bad>\S)|(?P<end>\Z))")
_HINTS = {
    "-": " (interval bounds are seconds >= 0)",
    "~": " (write '!' for negation)",
    "^": " (write '&' for and)",
    "=": " (predicates are written in(BODY, REGION))",
}
_PREDICATE_HINT = "a predicate like in(O1, goal)"


class _Token(NamedTuple):
    kind: str  # "name", "number", one of the punctuation characters, or "end"
    text: str
    column: int


def _tokenize(text: str) -> list[_Token]:
    tokens: list[_Token] = []
    append = tokens.append
    new = tuple.__new__  # a NamedTuple's own __new__ is Python code; this is the same tuple, 3x faster
    for m in _TOKEN.finditer(text):
        kind = m.lastgroup or "end"  # every match is one of the named groups
        if kind == "end":
            break
        word = m.group(kind)
        column = m.end() - len(word)
        if kind == "bad":
            raise STLSyntaxError(f"unknown token {word!r}{_HINTS.get(word, '')}", text, column)
        append(new(_Token, (word if kind == "punct" else kind, word, column)))
    append(_Token("end", "", len(text)))
    return tokens


class _Parser:
    def __init__(self, text: str) -> None:
        self.text = text
        self.tokens = _tokenize(text)
        self.pos = 0
        self.depth = 0

    # -- helpers ------------------------------------------------------------------------------------------
    def peek(self) -> _Token:
        return self.tokens[self.pos]

    def advance(self) -> _Token:
        tok = self.tokens[self.pos]
        if tok.kind != "end":  # the end token stays current
            self.pos += 1
        return tok

    def error(self, message: str, tok: _Token) -> STLSyntaxError:
        return STLSyntaxError(message, self.text, tok.column)

    def expect(self, kind: str, message: str) -> _Token:
        tok = self.peek()
        if tok.kind != kind:
            found = "end of formula" if tok.kind == "end" else repr(tok.text)
            raise self.error(f"{message}, found {found}", tok)
        return self.advance()

    def is_keyword(self, word: str) -> bool:
        tok = self.peek()
        return tok.kind == "name" and tok.text == word

    def nest(self, tok: _Token) -> None:
        self.depth += 1
        if self.depth > MAX_NESTING:
            raise self.error(f"formula nests deeper than {MAX_NESTING} levels of parentheses, '!', 'F' and 'G'; "
                             "write a chain a & b & c rather than nesting, or simplify (!!a is a)", tok)

    # -- grammar ------------------------------------------------------------------------------------------
    def formula(self) -> Formula:
        items = [self.conj()]
        while self.peek().kind == "|":
            self.advance()
            items.append(self.conj())
        return items[0] if len(items) == 1 else Or(tuple(items))

    def conj(self) -> Formula:
        items = [self.until()]
        while self.peek().kind == "&":
            self.advance()
            items.append(self.until())
        return items[0] if len(items) == 1 else And(tuple(items))

    def until(self) -> Formula:
        left = self.unary()
        if not self.is_keyword("U"):
            return left
        self.advance()
        a_s, b_s = self.interval("U")
        right = self.unary()
        if self.is_keyword("U"):
            raise self.error("'U' is not associative; add parentheses, e.g. (a U[0, 1] b) U[0, 2] c", self.peek())
        return Until(a_s, b_s, left, right)

    def unary(self) -> Formula:
        tok = self.peek()
        if tok.kind == "!":
            self.advance()
            self.nest(tok)
            child = self.unary()
            self.depth -= 1
            return Not(child)
        if tok.kind == "name" and tok.text in ("F", "G"):
            self.advance()
            a_s, b_s = self.interval(tok.text)
            self.nest(tok)
            child = self.unary()
            self.depth -= 1
            return Eventually(a_s, b_s, child) if tok.text == "F" else Always(a_s, b_s, child)
        return self.atom()

    def atom(self) -> Formula:
        tok = self.peek()
        if tok.kind == "(":
            self.advance()
            self.nest(tok)
            inner = self.formula()
            self.expect(")", f"expected ')' to close the '(' at column {tok.column}")
            self.depth -= 1
            return inner
        if tok.kind == "end":
            raise self.error(f"unexpected end of formula, expected {_PREDICATE_HINT}", tok)
        if tok.kind != "name":
            raise self.error(f"expected {_PREDICATE_HINT} before {tok.text!r}", tok)
        if tok.text == "in":
            return self.predicate()
        if tok.text in ("true", "false"):
            self.advance()
            return TrueFormula() if tok.text == "true" else FalseFormula()
        if tok.text == "U":
            raise self.error("'U' needs a formula on its left, e.g. in(A, r) U[0, 5] in(B, s)", tok)
        raise self.error(f"unknown name {tok.text!r}; expected {_PREDICATE_HINT}, '!', 'F[a,b]', 'G[a,b]', "
                         "'true', 'false' or '('", tok)

    def predicate(self) -> InRegion:
        self.advance()  # 'in'
        self.expect("(", "expected '(' after 'in', as in in(O1, goal)")
        body = self.expect("name", "expected a body name inside in(BODY, REGION)")
        self.expect(",", "expected ',' between body and region in in(BODY, REGION)")
        region = self.expect("name", "expected a region name inside in(BODY, REGION)")
        self.expect(")", f"expected ')' to close in({body.text}, {region.text}")
        return InRegion(body.text, region.text)

    def interval(self, op: str) -> tuple[float, float]:
        opening = self.expect("[", f"expected '[' after '{op}' (write {op}[a,b] with a, b in seconds)")
        a_tok = self.expect("number", "expected a number of seconds for the interval start")
        self.expect(",", "expected ',' between the interval bounds")
        b_tok = self.expect("number", "expected a number of seconds for the interval end")
        self.expect("]", "expected ']' after interval")
        a_s, b_s = float(a_tok.text), float(b_tok.text)
        if not (math.isfinite(a_s) and math.isfinite(b_s)):
            raise self.error(f"interval [{a_tok.text}, {b_tok.text}] must have finite bounds", opening)
        if a_s > b_s:
            raise self.error(f"interval [{a_tok.text}, {b_tok.text}] has a > b", opening)
        return a_s, b_s


def parse(text: str) -> Formula:
    """Parse STL text such as ``F[0,100] in(O1, goal) & G[0,100] !in(R1, W1)`` (bounds in seconds).

    Names match ``[A-Za-z_][A-Za-z0-9_]*``; ``F``, ``G``, ``U``, ``in``, ``true``, ``false`` are keywords only where
    the grammar expects an operator, so a body may still be called ``F``. Numbers: ``0``, ``2.5``, ``.5``, ``1e2``,
    ``1e-05``.

    Errors are :class:`STLSyntaxError` with the 0-based column of the offending token.

    Nesting (parentheses and the prefixes ``!``, ``F``, ``G``) is limited to :data:`MAX_NESTING` levels: every
    walker of the tree (robustness, the online monitor, printing, the MILP encoding) recurses once per level, and
    no task needs more than a handful. A flat chain ``a & b & c & ...`` is one level however long it is.
    """
    if not isinstance(text, str):
        raise STLSyntaxError(f"an STL formula must be a string, got {type(text).__name__}")
    parser = _Parser(text)
    result = parser.formula()
    tok = parser.peek()
    if tok.kind != "end":
        if tok.kind == ")":
            raise parser.error("unmatched ')'", tok)
        raise parser.error(f"unexpected {tok.text!r} after a complete formula; join formulas with '&' or '|'",
                           tok)
    return result
