"""Text to syntax tree: lark's LALR parser over ``grammar.lark``, then :mod:`._ast` nodes.

Newlines end statements in TMscript (TMscript 2.24 §3.8), but a newline may also sit where
no statement ends: between ``if (c)`` and its body, before ``{`` or ``else``, inside
parentheses or an array constant. :class:`_Newlines` keeps only the newlines that end a
statement (and adds one before a block's ``}``), so the grammar stays LALR(1).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from functools import cache
from importlib.resources import files
from typing import Any, TypedDict, cast

from lark import Lark, Token, Transformer, Tree, v_args
from lark.exceptions import UnexpectedCharacters, UnexpectedEOF, UnexpectedInput, UnexpectedToken
from lark.lark import PostLex
from lark.parsers.lalr_parser_state import ParserState
from lark.tree import Meta

from .._exceptions import TMScriptError, TMScriptSyntaxError
from . import _ast as a
from ._grammar_cache import cache_file, keep_parsed, load_parsed, parsed_file
from ._types import STRING_MAX, fits_f32

__all__ = ["MAX_ERRORS", "MAX_NESTING", "check_script", "parse_script"]

#: How deeply a script may nest: each operand of an operator, each call, block and
#: statement inside another is one level (``1+1+...+1`` nests once per ``+``). The
#: manual states no limit: this one is tmmaster's, as checking and running a script
#: takes a Python stack frame or two per level.
MAX_NESTING = 200

#: Words after which a ``{`` opens a block (anything else opens an array constant).
_BLOCK_OPENERS = frozenset({")", "else", "do", "define", "main", "closestop", "errorstop"})
#: Keywords whose parenthesised header is followed by a body (newlines there are dropped).
_HEADER_KEYWORDS = frozenset({"if", "for", "while", "switch"})
_PUNCT_TYPES = frozenset({"NAME", "STRING", "INT", "HEX", "BIN", "FLOAT", "TYPE", "CLASS"})


def _word(tok: Token) -> str:
    """A token's text when it is a keyword or punctuation, else its type (NAME, STRING...)."""
    return tok.type if tok.type in _PUNCT_TYPES else str(tok.value)


class _Layout:
    """Where the post-lexer stands: the open brackets and the newline not yet emitted.

    Each open bracket is one of "paren" (newlines inside are ignored), "header" (its
    ")" is followed by a body), "block", "do" (a do-while's body), "array".
    """

    def __init__(self) -> None:
        self.stack: list[str] = []
        self.prev: str | None = None  # the previous significant token's word
        self.pending: Token | None = None  # a newline not yet known to end a statement
        self.after_header = False  # the previous token closed an if/for/while/switch header
        self.after_do = False  # the previous token closed a do-while's body
        self.do_while = False  # the last while seen ends a do-while

    def newline(self, tok: Token) -> None:
        """Keep ``tok`` as pending when it may end a statement."""
        ignored = not self.stack or self.stack[-1] in ("paren", "header", "array")
        if (
            self.pending is None
            and not ignored
            and not self.after_header
            and self.prev not in ("{", "else", "do", None)
            and not self.after_do
        ):
            self.pending = tok

    def flush_before(self, word: str, tok: Token) -> Token | None:
        """The pending newline to emit before ``tok``, or None when ``tok`` cancels it."""
        if self.pending is not None and (
            word in ("{", "else") or (word == "while" and self.after_do)
        ):
            self.pending = None
        if (
            word == "}"
            and self.stack
            and self.stack[-1] in ("block", "do")
            and self.pending is None
            and self.prev not in ("{", None, "_NL")
        ):
            # The statement before a "}" on its own line keeps its own newline (an
            # error there points at the end of that line, not at the "}").
            self.pending = Token.new_borrow_pos("_NL", "\n", tok)
        pending, self.pending = self.pending, None
        if pending is not None:
            self.prev = "_NL"
        return pending

    def bracket(self, word: str, tok: Token) -> Token:
        """Track ``tok``'s bracket; a block's braces become ``_LB`` / ``_RB``."""
        closed_header = self.after_header
        self.after_header = False
        if word == "while":
            self.do_while = self.after_do  # the while of a do-while: no body follows
        self.after_do = False
        if word in ("(", "[", "{"):
            self.stack.append(self._opened(word, closed_header))
        elif word in (")", "]", "}") and self.stack:
            top = self.stack.pop()
            self.after_header = top == "header"
            self.after_do = top == "do"
            if word == "}" and top in ("block", "do"):
                tok = Token.new_borrow_pos("_RB", "}", tok)
        if word == "{" and self.stack[-1] in ("block", "do"):
            tok = Token.new_borrow_pos("_LB", "{", tok)
        self.prev = word
        return tok

    def _opened(self, word: str, closed_header: bool) -> str:
        """What the bracket ``word`` (``(``, ``[`` or ``{``) opens."""
        prev = self.prev
        if word == "(":
            header = prev in _HEADER_KEYWORDS and not (prev == "while" and self.do_while)
            return "header" if header else "paren"
        if word == "[":
            return "paren"
        # After ")" only an if/for/while/switch header or a function's parameters open
        # a block: "(int[]){...}" is a cast of an array constant.
        opens_block = prev in _BLOCK_OPENERS and (prev != ")" or closed_header or not self.stack)
        if opens_block or prev == "_NL" or prev is None:
            return "do" if prev == "do" else "block"
        return "array"


class _Newlines(PostLex):
    """Keep a newline only where it ends a statement."""

    always_accept = ("_NL",)

    def process(self, stream: Iterator[Token]) -> Iterator[Token]:
        layout = _Layout()
        for tok in stream:
            if tok.type == "_NL":
                layout.newline(tok)
                continue
            word = _word(tok)
            pending = layout.flush_before(word, tok)
            if pending is not None:
                yield pending
            yield layout.bracket(word, tok)
        if layout.pending is not None and layout.stack:
            yield layout.pending


@cache
def _parser() -> Lark:
    """The parser, built once per process; its tables are kept in this user's private
    cache folder when there is one (:mod:`._grammar_cache`)."""
    grammar = files(__package__).joinpath("grammar.lark").read_text(encoding="utf-8")
    return build_parser(grammar, cache_file(grammar))


def build_parser(grammar: str, cache: str | None) -> Lark:
    """lark's LALR parser of ``grammar``, its tables loaded from or saved to ``cache``.

    Args:
        grammar: The grammar's text.
        cache: The file lark keeps the tables in (a pickle: a path in a private folder
            only, see :mod:`._grammar_cache`), or None to build them in memory.

    Returns:
        The parser.
    """
    return Lark(
        grammar,
        parser="lalr",
        lexer="basic",
        postlex=_Newlines(),
        propagate_positions=True,
        maybe_placeholders=True,
        cache=cache if cache is not None else False,
    )


class _Where(TypedDict):
    line: int
    column: int


def _pos(meta: Meta) -> _Where:
    return {"line": meta.line, "column": meta.column}


def _tpos(tok: Token) -> _Where:
    return {"line": tok.line or 0, "column": tok.column or 0}


def _string_value(text: str) -> str:
    return text[1:-1].replace('""', '"')


def _exprs(items: list[object]) -> tuple[a.Expr, ...]:
    return tuple(cast(a.Expr, item) for item in items if item is not None)


def _smallest_int_type(value: int) -> str:
    # The smallest type the constant fits, byte first (TMscript 2.24 §2.2, p. 14).
    if 0 <= value <= 255:
        return "byte"
    if -(2**31) <= value < 2**31:
        return "int"
    return "double"


@v_args(meta=True)
class _ToAst(Transformer[Token, object]):
    """lark's tree to :mod:`._ast` nodes."""

    def start(self, meta: Meta, children: list[object]) -> a.Script:
        define: list[a.Statement] = []
        blocks: dict[str, a.Block] = {}
        functions: list[a.FunctionDef] = []
        for child in children:
            if isinstance(child, a.FunctionDef):
                functions.append(child)
            else:
                kind, node = cast(tuple[str, object], child)
                if kind == "define":
                    define.extend(cast(tuple[a.Statement, ...], node))
                else:
                    if kind in blocks:
                        block = cast(a.Block, node)
                        raise TMScriptSyntaxError(
                            f"a second {kind} section", line=block.line, column=block.column
                        )
                    blocks[kind] = cast(a.Block, node)
        line = meta.line if not meta.empty else 1
        column = meta.column if not meta.empty else 1
        return a.Script(
            line=line,
            column=column,
            define=tuple(define),
            main=blocks.get("main"),
            closestop=blocks.get("closestop"),
            errorstop=blocks.get("errorstop"),
            functions=tuple(functions),
        )

    def define_section(self, meta: Meta, children: list[object]) -> tuple[str, object]:
        return ("define", tuple(children))

    def main_section(self, meta: Meta, children: list[object]) -> tuple[str, object]:
        return ("main", children[0])

    def closestop_section(self, meta: Meta, children: list[object]) -> tuple[str, object]:
        return ("closestop", children[0])

    def errorstop_section(self, meta: Meta, children: list[object]) -> tuple[str, object]:
        return ("errorstop", children[0])

    def function_def(self, meta: Meta, children: list[object]) -> a.FunctionDef:
        ret, name, *rest = children
        body = cast(a.Block, rest[-1])
        params = tuple(cast(a.Param, p) for p in rest[:-1] if p is not None)
        return a.FunctionDef(
            **_pos(meta),
            return_type=cast(a.TypeSpec, ret),
            name=str(name),
            params=params,
            body=body,
        )

    def return_type(self, meta: Meta, children: list[object]) -> a.TypeSpec:
        child = children[0]
        if isinstance(child, a.TypeSpec):
            return child
        return a.TypeSpec(line=meta.line, column=meta.column, base="void")

    def param(self, meta: Meta, children: list[object]) -> a.Param:
        return a.Param(**_pos(meta), type=cast(a.TypeSpec, children[0]), name=str(children[1]))

    def type_spec(self, meta: Meta, children: list[object]) -> a.TypeSpec:
        base = str(children[0])
        return a.TypeSpec(
            line=meta.line, column=meta.column, base=base, array=children[1] is not None
        )

    def block(self, meta: Meta, children: list[object]) -> a.Block:
        return a.Block(**_pos(meta), statements=tuple(cast(a.Statement, c) for c in children))

    def declaration(self, meta: Meta, children: list[object]) -> a.Declaration:
        spec, name, init = children
        return a.Declaration(
            **_pos(meta),
            type=cast(a.TypeSpec, spec),
            name=str(name),
            init=cast(a.Expr | None, init),
        )

    def class_declaration(self, meta: Meta, children: list[object]) -> a.ClassDeclaration:
        cls, name, *args = children
        return a.ClassDeclaration(**_pos(meta), cls=str(cls), name=str(name), args=_exprs(args))

    def expr_statement(self, meta: Meta, children: list[object]) -> a.ExprStatement:
        return a.ExprStatement(**_pos(meta), expr=cast(a.Expr, children[0]))

    def break_statement(self, meta: Meta, children: list[object]) -> a.Break:
        return a.Break(**_pos(meta))

    def continue_statement(self, meta: Meta, children: list[object]) -> a.Continue:
        return a.Continue(**_pos(meta))

    def return_statement(self, meta: Meta, children: list[object]) -> a.Return:
        return a.Return(**_pos(meta), value=cast(a.Expr | None, children[0]))

    def if_statement(self, meta: Meta, children: list[object]) -> a.If:
        cond, then, otherwise = children
        return a.If(
            **_pos(meta),
            condition=cast(a.Expr, cond),
            then=cast(a.Statement, then),
            otherwise=cast(a.Statement | None, otherwise),
        )

    def switch_statement(self, meta: Meta, children: list[object]) -> a.Switch:
        subject, *cases = children
        return a.Switch(
            **_pos(meta),
            subject=cast(a.Expr, subject),
            cases=tuple(cast(a.Case, c) for c in cases),
        )

    def case_clause(self, meta: Meta, children: list[object]) -> a.Case:
        label, *body = children
        op, value = cast(tuple[str, a.Expr], label)
        return a.Case(
            **_pos(meta), op=op, value=value, body=tuple(cast(a.Statement, s) for s in body)
        )

    def default_clause(self, meta: Meta, children: list[object]) -> a.Case:
        return a.Case(
            **_pos(meta), op="==", value=None, body=tuple(cast(a.Statement, s) for s in children)
        )

    def case_label(self, meta: Meta, children: list[object]) -> tuple[str, a.Expr]:
        if len(children) == 2:
            return (str(children[0]), cast(a.Expr, children[1]))
        return ("==", cast(a.Expr, children[0]))

    def for_statement(self, meta: Meta, children: list[object]) -> a.For:
        init, cond, step, body = children
        init_stmt: a.Statement | None
        if init is None or isinstance(init, a.Declaration):
            init_stmt = init
        else:
            expr = cast(a.Expr, init)
            init_stmt = a.ExprStatement(line=expr.line, column=expr.column, expr=expr)
        return a.For(
            **_pos(meta),
            init=init_stmt,
            condition=cast(a.Expr | None, cond),
            step=cast(a.Expr | None, step),
            body=cast(a.Statement, body),
        )

    def while_statement(self, meta: Meta, children: list[object]) -> a.While:
        return a.While(
            **_pos(meta), condition=cast(a.Expr, children[0]), body=cast(a.Statement, children[1])
        )

    def do_statement(self, meta: Meta, children: list[object]) -> a.DoWhile:
        return a.DoWhile(
            **_pos(meta), body=cast(a.Statement, children[0]), condition=cast(a.Expr, children[1])
        )

    # ---- expressions ----

    def assign(self, meta: Meta, children: list[object]) -> a.Assign:
        target, op, value = children
        return a.Assign(
            **_pos(meta), op=str(op), target=cast(a.Expr, target), value=cast(a.Expr, value)
        )

    def assign_op(self, meta: Meta, children: list[object]) -> str:
        return str(children[0])

    def ternary(self, meta: Meta, children: list[object]) -> a.Ternary:
        cond, then, otherwise = children
        return a.Ternary(
            **_pos(meta),
            condition=cast(a.Expr, cond),
            then=cast(a.Expr, then),
            otherwise=cast(a.Expr, otherwise),
        )

    def logic_or(self, meta: Meta, children: list[object]) -> a.Logic:
        return a.Logic(
            **_pos(meta), op="||", left=cast(a.Expr, children[0]), right=cast(a.Expr, children[1])
        )

    def logic_and(self, meta: Meta, children: list[object]) -> a.Logic:
        return a.Logic(
            **_pos(meta), op="&&", left=cast(a.Expr, children[0]), right=cast(a.Expr, children[1])
        )

    def binary(self, meta: Meta, children: list[object]) -> a.Binary:
        left, op, right = children
        return a.Binary(
            **_tpos(cast(Token, op)),
            op=str(op),
            left=cast(a.Expr, left),
            right=cast(a.Expr, right),
        )

    def unary(self, meta: Meta, children: list[object]) -> a.Expr:
        op, operand = children
        # -2147483648 and friends are constants, not negations of an out-of-range constant.
        if str(op) == "-" and isinstance(operand, a.Literal) and operand.type != "string":
            value = operand.value
            if isinstance(value, int | float) and not isinstance(value, bool):
                neg = -value
                typ = _smallest_int_type(neg) if isinstance(neg, int) else operand.type
                if typ == "byte":
                    typ = "int"  # -5 does not fit a byte
                return a.Literal(**_pos(meta), value=neg, type=typ)
        return a.Unary(**_pos(meta), op=str(op), operand=cast(a.Expr, operand))

    def prefix(self, meta: Meta, children: list[object]) -> a.IncDec:
        op, target = children
        return a.IncDec(**_pos(meta), op=str(op), target=cast(a.Expr, target), prefix=True)

    def postfix(self, meta: Meta, children: list[object]) -> a.IncDec:
        target, op = children
        return a.IncDec(**_pos(meta), op=str(op), target=cast(a.Expr, target), prefix=False)

    def cast(self, meta: Meta, children: list[object]) -> a.Cast:
        return a.Cast(
            **_pos(meta), type=cast(a.TypeSpec, children[0]), operand=cast(a.Expr, children[1])
        )

    def index(self, meta: Meta, children: list[object]) -> a.Index:
        return a.Index(
            **_pos(meta), target=cast(a.Expr, children[0]), index=cast(a.Expr, children[1])
        )

    def call(self, meta: Meta, children: list[object]) -> a.Call:
        name, *args = children
        return a.Call(**_pos(meta), name=str(name), args=_exprs(args))

    def method_call(self, meta: Meta, children: list[object]) -> a.MethodCall:
        target, method, *args = children
        return a.MethodCall(
            **_pos(meta), target=cast(a.Expr, target), method=str(method), args=_exprs(args)
        )

    def name(self, meta: Meta, children: list[object]) -> a.Expr:
        word = str(children[0])
        # Boolean constants are case sensitive: true/True, false/False (§2.2, p. 16).
        if word in ("true", "True"):
            return a.Literal(**_pos(meta), value=True, type="bool")
        if word in ("false", "False"):
            return a.Literal(**_pos(meta), value=False, type="bool")
        if word == "empty":
            return a.Literal(**_pos(meta), value="", type="string")
        if word in ("newline", "NewLine"):
            return a.Literal(**_pos(meta), value="\r\n", type="string")
        return a.Name(**_pos(meta), name=word)

    def int_literal(self, meta: Meta, children: list[object]) -> a.Literal:
        value = int(str(children[0]), 10)
        return a.Literal(**_pos(meta), value=value, type=_smallest_int_type(value))

    def hex_literal(self, meta: Meta, children: list[object]) -> a.Literal:
        text = str(children[0])
        value = int(text[2:], 16)
        return a.Literal(**_pos(meta), value=value, type=_smallest_int_type(value), written=text)

    def bin_literal(self, meta: Meta, children: list[object]) -> a.Literal:
        text = str(children[0])
        value = int(text[2:], 2)
        return a.Literal(**_pos(meta), value=value, type=_smallest_int_type(value), written=text)

    def float_literal(self, meta: Meta, children: list[object]) -> a.Literal:
        text = str(children[0])
        value = float(text)
        # float when it fits a float's range and 7 significant digits, else double (§2.2).
        digits = len(text.lower().split("e")[0].replace(".", "").lstrip("0"))
        typ = "float" if fits_f32(value) and digits <= 7 else "double"
        return a.Literal(**_pos(meta), value=value, type=typ)

    def string_literal(self, meta: Meta, children: list[object]) -> a.Literal:
        value = _string_value(str(children[0]))
        if len(value) > STRING_MAX:
            raise TMScriptSyntaxError(
                f"a string holds at most {STRING_MAX} characters, not {len(value)}",
                **_pos(meta),
            )
        return a.Literal(**_pos(meta), value=value, type="string")

    def array_literal(self, meta: Meta, children: list[object]) -> a.ArrayLiteral:
        return a.ArrayLiteral(**_pos(meta), items=_exprs(children))


def _error_position(exc: UnexpectedInput, text: str) -> tuple[int, int]:
    token = getattr(exc, "token", None)
    if isinstance(token, Token) and token.type == "$END":
        return _end_position(token, text)
    line = getattr(exc, "line", -1)
    column = getattr(exc, "column", -1)
    if isinstance(line, int) and line > 0 and isinstance(column, int) and column > 0:
        return line, column
    return _text_end(text)


def _text_end(text: str) -> tuple[int, int]:
    """Just after the last character that is not white space."""
    lines = text.rstrip().splitlines() or [""]
    return len(lines), len(lines[-1]) + 1


def _end_position(end: Token, text: str) -> tuple[int, int]:
    """Where the script ends too early: just after its last token.

    lark's end-of-input token borrows the last token's position: after a newline, that
    newline's (the end of its line); after anything else, where that token ends.
    """
    line, column = end.line, end.column
    end_line, end_column = end.end_line, end.end_column
    if not (isinstance(line, int) and line > 0 and isinstance(column, int) and column > 0):
        return _text_end(text)
    if isinstance(end_line, int) and end_line == line and isinstance(end_column, int):
        return end_line, end_column
    return line, column


#: Terminals that close a bracket, as the script writes them.
_CLOSERS = {"RPAR": "')'", "RSQB": "']'", "RBRACE": "'}'", "_RB": "'}'"}
#: A parser state expecting one of these (and nothing that starts a statement or
#: ends one) wants an operand: the expression before the token is incomplete.
_OPERAND_STARTS = frozenset({"NAME", "INT", "LPAR"})
_STATEMENT_STARTS = frozenset({"_NL", "_RB", "IF", "TYPE", "RPAR", "RSQB", "COMMA", "SEMICOLON"})


def _expected_hint(exc: UnexpectedInput) -> str:
    """What the parser wanted instead, when that is one thing to name."""
    expected = set(getattr(exc, "expected", None) or ())
    if len(expected) == 1 and next(iter(expected)) in _CLOSERS:
        return f", expected {_CLOSERS[next(iter(expected))]}"
    if expected >= _OPERAND_STARTS and not expected & _STATEMENT_STARTS:
        return ": an operand is missing"
    return ""


#: How the error at the end of a script that ends too early begins.
_AT_THE_END = "unexpected end of the script"


def _describe(exc: UnexpectedInput) -> str:
    if isinstance(exc, UnexpectedCharacters):
        if exc.char == '"':
            return "a string constant without its closing '\"' on this line"
        return f"unexpected character {exc.char!r}"
    hint = _expected_hint(exc)
    if isinstance(exc, UnexpectedEOF) or (
        isinstance(exc, UnexpectedToken) and exc.token.type == "$END"
    ):
        return _AT_THE_END + (hint or " (a missing '}' or ')'?)")
    if isinstance(exc, UnexpectedToken):
        tok = exc.token
        if tok.type == "_NL":
            return f"unexpected end of line{hint}"
        return f"unexpected {str(tok.value)!r}{hint}"
    return "syntax error"


def _syntax_error(exc: UnexpectedInput, text: str) -> TMScriptSyntaxError:
    line, column = _error_position(exc, text)
    return TMScriptSyntaxError(_describe(exc), line=line, column=column)


#: What ``eval`` wraps an expression in (:func:`expression_script`): the expression sits
#: on line 1, after these characters.
_EXPRESSION_PREFIX = "main {"
#: An error past the expression's end, as the wrapping's "}" or the end of the text saw it.
_PAST_THE_END = re.compile(r"^unexpected ('\}'|end of the script|end of line)")


def expression_script(expression: str) -> str:
    """The Script Project that evaluates ``expression`` (on one line) as its one statement."""
    return f"{_EXPRESSION_PREFIX}{expression}\n}}\n"


def expression_error(exc: TMScriptError, expression: str) -> TMScriptError:
    """``exc``, raised for :func:`expression_script`'s text, placed in ``expression`` alone.

    An error past the expression (at the "}" it is wrapped in, or at the end of the text)
    points just after the expression's last character: that is where it ends too early.

    Args:
        exc: The error, with its position in the wrapped text.
        expression: The expression as the user wrote it.

    Returns:
        The same kind of error on line 1, its column counted in ``expression``.
    """
    end = len(expression.rstrip()) + 1
    reason = exc.reason
    if exc.line > 1:
        column = end
        reason = _PAST_THE_END.sub("unexpected end of the expression", reason)
    else:
        column = min(max(1, exc.column - len(_EXPRESSION_PREFIX)), len(expression) + 1)
        reason = reason.replace("unexpected end of line", "unexpected end of the expression")
    return type(exc)(reason, line=1, column=column)


def _check_nesting(tree: Tree[Token]) -> None:
    """Raise TMScriptSyntaxError where ``tree`` nests deeper than :data:`MAX_NESTING`.

    Walked with a stack of its own (the tree may be as deep as the text is long).
    """
    stack: list[tuple[Tree[Token], int]] = [(tree, 0)]
    while stack:
        node, depth = stack.pop()
        if depth > MAX_NESTING:
            line, column = _tree_position(node)
            raise TMScriptSyntaxError(
                f"the script nests more than {MAX_NESTING} levels deep here"
                " (split the expression or the blocks)",
                line=line,
                column=column,
            )
        stack.extend((child, depth + 1) for child in node.children if isinstance(child, Tree))


def _tree_position(node: Tree[Token]) -> tuple[int, int]:
    """Where ``node`` starts: its position, else its first token's."""
    meta = node.meta
    if not meta.empty:
        return meta.line, meta.column
    for token in node.scan_values(lambda v: isinstance(v, Token)):
        return token.line or 1, token.column or 1
    return 1, 1


def parse_script(text: str) -> a.Script:
    """Parse a Script Project's text into its syntax tree.

    A long script's tree is kept in this user's private cache folder, and read back from
    there when the same script is parsed again (:func:`._grammar_cache.parsed_file`).

    :param text: the whole script.
    :returns: the :class:`._ast.Script`.
    :raises TMScriptSyntaxError: the text is not TMscript, nests more than
        :data:`MAX_NESTING` levels deep or has a string constant over
        :data:`~._types.STRING_MAX` characters; ``line``/``column`` say where.
    """
    path = parsed_file(text)
    kept = load_parsed(path)
    if isinstance(kept, a.Script):
        return kept
    script = _parse(text)
    keep_parsed(path, script)
    return script


def _parse(text: str) -> a.Script:
    """:func:`parse_script` by lark's parser."""
    try:
        tree = _parser().parse(text)
        _check_nesting(tree)
        return cast(a.Script, _ToAst().transform(tree))
    except UnexpectedInput as exc:
        raise _syntax_error(exc, text) from None
    except Exception as exc:  # a TMScriptSyntaxError raised inside the transformer
        inner = getattr(exc, "orig_exc", None)
        if isinstance(inner, TMScriptSyntaxError):
            raise inner from None
        raise


#: The most syntax errors :func:`check_script` reports for one script.
MAX_ERRORS = 100
#: Tokens that end a statement or a block: where the parser picks up after an error.
_SYNC = ("_NL", "_RB")


def check_script(text: str) -> tuple[a.Script | None, list[TMScriptSyntaxError]]:
    """Parse a Script Project as :func:`parse_script` does, but find all its syntax errors.

    After a syntax error the parser skips to the end of the statement (a whole block
    when one opens on the way) and goes on from there; an unknown character is skipped.

    :param text: the whole script.
    :returns: ``(script, [])`` when the script has no syntax error, else ``(None,
        errors)``: in the order of the text, the first of each line, at most
        :data:`MAX_ERRORS`; the first is the one :func:`parse_script` raises.
    """
    try:
        return parse_script(text), []
    except TMScriptSyntaxError as first:
        found = _recovered_errors(text)
        errors = _first_per_line([first, *found])
        return None, errors[:MAX_ERRORS]


def _first_per_line(errors: list[TMScriptSyntaxError]) -> list[TMScriptSyntaxError]:
    """The first of ``errors`` on each line, in the order of the text; and the end of the
    script coming too early (a block not closed), wherever it is."""
    by_line: dict[tuple[int, bool], TMScriptSyntaxError] = {}
    for error in errors:
        by_line.setdefault((error.line, error.reason.startswith(_AT_THE_END)), error)
    return sorted(by_line.values(), key=lambda e: (e.line, e.column))


def _recovered_errors(text: str) -> list[TMScriptSyntaxError]:
    """Every syntax error of ``text``: its unknown characters, then (with each of them
    read as a space) the grammar's errors in the order of the text."""
    lexical, text = _unknown_characters(text)
    if len(lexical) >= MAX_ERRORS:
        return lexical
    try:
        found = _parse_recovering(text)
    except UnexpectedCharacters:  # pragma: no cover - each one was replaced by a space
        found = []
    return lexical + sorted(found, key=lambda e: (e.line, e.column))


def _unknown_characters(text: str) -> tuple[list[TMScriptSyntaxError], str]:
    """The characters no token starts with (at most :data:`MAX_ERRORS`), and ``text``
    with each of them replaced by a space.

    Lexing starts again just after each one: a token would have started there, so the
    rest reads as it would have.
    """
    errors: list[TMScriptSyntaxError] = []
    chars = list(text)
    offset = 0
    while len(errors) < MAX_ERRORS:
        try:
            for _ in _parser().lex(text[offset:]):
                pass
        except UnexpectedCharacters as exc:
            at = offset + (exc.pos_in_stream or 0)
            line = text.count("\n", 0, at) + 1
            column = at - (text.rfind("\n", 0, at) + 1) + 1
            errors.append(TMScriptSyntaxError(_describe(exc), line=line, column=column))
            chars[at] = " "
            offset = at + 1
        else:
            break
    return errors, "".join(chars)


def _parse_recovering(text: str) -> list[TMScriptSyntaxError]:
    """The grammar's errors in ``text``, which has no unknown character."""
    parser = _parser().parse_interactive(text)
    state = parser.parser_state
    tokens: Iterator[Token] = parser.lexer_thread.lex(state)  # type: ignore[no-untyped-call]
    stream = iter(tokens)
    errors: list[TMScriptSyntaxError] = []
    last: Token | None = None
    for tok in stream:
        last = tok
        try:
            state.feed_token(tok)
        except UnexpectedToken as exc:
            errors.append(_syntax_error(exc, text))
            last = None if len(errors) >= MAX_ERRORS else _resync(state, tok, stream)
            if last is None:
                return errors
    end = Token.new_borrow_pos("$END", "", last) if last is not None else Token("$END", "")
    try:
        state.feed_token(end, True)
    except UnexpectedToken as exc:
        errors.append(_syntax_error(exc, text))
    return errors


def _resync(state: ParserState[Any], bad: Token, stream: Iterator[Token]) -> Token | None:
    """After ``bad`` was refused: skip to the statement's end and drop the statement.

    Tokens are skipped up to the next newline or block end outside any block opened on
    the way; then the parser's stack is unwound until that token fits (the statement so
    far, cut short) or a statement may begin there (the token is dropped).

    :returns: the token it picked up at (fed or dropped); None when the script ended first.
    """
    depth = 0
    tok: Token | None = bad
    while tok is not None and not (depth == 0 and tok.type in _SYNC):
        if tok.type == "_LB":
            depth += 1
        elif tok.type == "_RB":
            depth -= 1
        tok = next(stream, None)
    if tok is None:
        return None
    table = state.parse_conf.states
    while True:
        try:
            state.copy(deepcopy_values=False).feed_token(tok)
        except UnexpectedToken:
            pass
        else:
            state.feed_token(tok)
            return tok
        at_boundary = tok.type == "_NL" and "_RB" in table[state.state_stack[-1]]
        if at_boundary or len(state.state_stack) <= 1:
            return tok  # dropped
        state.state_stack.pop()
        state.value_stack.pop()
