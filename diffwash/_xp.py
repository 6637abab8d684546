r"""The array namespace the model is written against: JAX, or GLSL source.

The watercolour model (`diffwash.km`, `diffwash.shading`, the sRGB curve of
`diffwash.colorimetry`) is written once, against the handful of operations
below, and evaluated two ways:

- on arrays, through `jax.numpy` (`JAX`): what the renderer, the LUT baker and
  the fits run;
- on symbolic values (`Expr`), which record the arithmetic as GLSL source: what
  `diffwash._glsl` writes into the exported shaders.

So the shaders are generated from the very functions the renderer runs; their
constants (epsilons, series coefficients and lengths) come from the same Python
values, never retyped. A function picks its namespace from its arguments
(`namespace(*args)`): any `Expr` among them means GLSL.

Conventions shared by both: a *point value* is a per-point scalar (JAX shape
`(*b,)`, GLSL `float`) and a *vector* holds channels on the last axis (JAX
`(*b, C)`, GLSL `vecC`); `expand` turns a point value into a vector-broadcastable
one (JAX `x[..., None]`, GLSL the same float), `dot` sums the last axis.
Booleans are the results of comparisons; `where(c, a, b)` selects.

Functions decorated with `shader_function` become GLSL functions of their own
(called, not inlined) when traced, which keeps the generated source readable.
"""

from __future__ import annotations

import contextlib
import functools
import inspect
import itertools
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import jax.numpy as jnp

__all__ = ["JAX", "GLSL", "Expr", "namespace", "shader_function", "trace_function", "float_literal"]


class _Jax:
    """The JAX namespace: thin names over `jax.numpy`."""

    name = "jax"

    @staticmethod
    def asfloat(*xs: Any) -> list[Any]:
        """The arguments as arrays of one floating dtype (JAX's default for Python numbers)."""
        dtype = jnp.result_type(*xs, float)
        return [jnp.asarray(x, dtype) for x in xs]

    where = staticmethod(jnp.where)
    clip = staticmethod(jnp.clip)
    minimum = staticmethod(jnp.minimum)
    maximum = staticmethod(jnp.maximum)
    exp = staticmethod(jnp.exp)
    expm1 = staticmethod(jnp.expm1)
    log = staticmethod(jnp.log)
    sqrt = staticmethod(jnp.sqrt)
    abs = staticmethod(jnp.abs)
    floor = staticmethod(jnp.floor)
    sin = staticmethod(jnp.sin)
    cos = staticmethod(jnp.cos)

    @staticmethod
    def power(x: Any, p: float) -> Any:
        return x**p

    @staticmethod
    def dot(a: Any, b: Any, keepdims: bool = False) -> Any:
        return jnp.sum(a * b, axis=-1, keepdims=keepdims)

    @staticmethod
    def expand(x: Any) -> Any:
        return jnp.asarray(x)[..., None]

    @staticmethod
    def logical_and(a: Any, b: Any) -> Any:
        return a & b

    @staticmethod
    def logical_or(a: Any, b: Any) -> Any:
        return a | b

    @staticmethod
    def stack(xs: Sequence[Any]) -> Any:
        """Point values as the channels of a vector (the last axis)."""
        return jnp.stack(jnp.broadcast_arrays(*xs), axis=-1)


JAX = _Jax()


# --- GLSL -------------------------------------------------------------------------------------------


def float_literal(x: float) -> str:
    """A GLSL float literal for `x`, exact to float32 (`1.0`, `0.5`, `1e-06`)."""
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"no GLSL literal for {x}")
    s = repr(x)
    if "e" in s or "E" in s:
        mant, exp = s.lower().split("e")
        if "." not in mant:
            mant += ".0"
        return f"{mant}e{int(exp)}"
    return s if "." in s else s + ".0"


def _type(size: int, boolean: bool = False) -> str:
    if size == 1:
        return "bool" if boolean else "float"
    return f"{'b' if boolean else ''}vec{size}"


@dataclass(eq=False)
class Expr:
    """A symbolic GLSL value: its source, its size (1 = float, 2-4 = vecN) and whether it is boolean.

    Arithmetic, comparisons and the namespace's functions on `Expr`s build new
    ones; `trace_function` turns a traced function's results into GLSL source.
    Sub-expressions used more than once become named locals.
    """

    code: str
    size: int = 1
    boolean: bool = False
    args: tuple["Expr", ...] = ()
    atom: bool = False  # a name or a literal: never hoisted
    out: bool = False  # an out parameter of a call statement: declared before it
    prec: int = 9  # operator precedence of the source: 0 comparison, 1 + -, 2 * /, 3 unary, 9 self-delimiting
    id: int = field(default_factory=itertools.count().__next__)

    @property
    def type(self) -> str:
        return _type(self.size, self.boolean)

    # Arithmetic ------------------------------------------------------------------------------------
    def _bin(self, other: Any, op: str, reverse: bool = False) -> "Expr":
        a, b = (_as_expr(other), self) if reverse else (self, _as_expr(other))
        return _node(f"{{0}} {op} {{1}}", _broadcast(a, b), (a, b), prec=_PREC[op])

    def __add__(self, o: Any) -> "Expr":
        return self._bin(o, "+")

    def __radd__(self, o: Any) -> "Expr":
        return self._bin(o, "+", True)

    def __sub__(self, o: Any) -> "Expr":
        return self._bin(o, "-")

    def __rsub__(self, o: Any) -> "Expr":
        return self._bin(o, "-", True)

    def __mul__(self, o: Any) -> "Expr":
        return self._bin(o, "*")

    def __rmul__(self, o: Any) -> "Expr":
        return self._bin(o, "*", True)

    def __truediv__(self, o: Any) -> "Expr":
        return self._bin(o, "/")

    def __rtruediv__(self, o: Any) -> "Expr":
        return self._bin(o, "/", True)

    def __neg__(self) -> "Expr":
        return _node("-{0}", self.size, (self,), prec=3)

    def __pow__(self, p: Any) -> "Expr":
        return GLSL.power(self, p)

    # Comparisons: scalars with the operators, vectors with GLSL's componentwise functions ----------
    def _cmp(self, other: Any, op: str, fn: str) -> "Expr":
        a, b = self, _as_expr(other)
        size = _broadcast(a, b)
        if size == 1:
            return _node(f"{{0}} {op} {{1}}", 1, (a, b), boolean=True, prec=0)
        return _node(f"{fn}({{0}}, {{1}})", size, (_widen(a, size), _widen(b, size)), boolean=True)

    def __lt__(self, o: Any) -> "Expr":
        return self._cmp(o, "<", "lessThan")

    def __le__(self, o: Any) -> "Expr":
        return self._cmp(o, "<=", "lessThanEqual")

    def __gt__(self, o: Any) -> "Expr":
        return self._cmp(o, ">", "greaterThan")

    def __ge__(self, o: Any) -> "Expr":
        return self._cmp(o, ">=", "greaterThanEqual")

    def __eq__(self, o: Any) -> "Expr":  # type: ignore[override]
        return self._cmp(o, "==", "equal")

    def __ne__(self, o: Any) -> "Expr":  # type: ignore[override]
        return self._cmp(o, "!=", "notEqual")

    __hash__ = object.__hash__

    def __and__(self, o: Any) -> "Expr":
        return GLSL.logical_and(self, o)

    def __or__(self, o: Any) -> "Expr":
        return GLSL.logical_or(self, o)

    def __invert__(self) -> "Expr":
        if self.size != 1:
            return _node("not({0})", self.size, (self,), boolean=True)
        return _node("!{0}", 1, (self,), boolean=True, prec=3)

    def __bool__(self) -> bool:
        raise TypeError("a symbolic GLSL value has no truth value: use where()")

    def __getitem__(self, i: int) -> "Expr":
        if not isinstance(i, int) or not 0 <= i < self.size or self.size == 1:
            raise IndexError(f"cannot index a {self.type} with {i!r}")
        return _node("{0}." + "xyzw"[i], 1, (self,), boolean=self.boolean)


_PREC = {"+": 1, "-": 1, "*": 2, "/": 2}


def _as_expr(x: Any) -> Expr:
    if isinstance(x, Expr):
        return x
    if isinstance(x, bool):
        return Expr("true" if x else "false", 1, True, atom=True)
    code = float_literal(float(x))
    return Expr(code, 1, atom=True, prec=3 if code.startswith("-") else 9)


def _broadcast(a: Expr, b: Expr) -> int:
    if a.size != b.size and 1 not in (a.size, b.size):
        raise TypeError(f"cannot combine a {a.type} and a {b.type}")
    return max(a.size, b.size)


def _widen(x: Expr, size: int) -> Expr:
    if x.size == size:
        return x
    if x.atom:
        return Expr(f"{_type(size, x.boolean)}({x.code})", size, x.boolean, atom=True)
    return _node(f"{_type(size, x.boolean)}({{0}})", size, (x,), boolean=x.boolean)


_memo: dict[tuple, Expr] = {}


def _node(template: str, size: int, args: tuple[Expr, ...], *, boolean: bool = False, prec: int = 9) -> Expr:
    """A new node, or the identical one already built (so a repeated sub-expression is computed once)."""
    key = (template, size, boolean, prec, tuple(a.id if not a.atom else ("atom", a.code) for a in args))
    if size == 0:  # a call statement with out parameters is never shared
        return Expr(template, size, boolean, args, prec=prec)
    hit = _memo.get(key)
    if hit is None:
        hit = _memo[key] = Expr(template, size, boolean, args, prec=prec)
    return hit


def _call(fn: str, size: int, *args: Any) -> Expr:
    xs = tuple(_as_expr(a) for a in args)
    slots = ", ".join(f"{{{i}}}" for i in range(len(xs)))
    return _node(f"{fn}({slots})", size, xs)


class _Glsl:
    """The GLSL namespace: each operation returns an `Expr` recording its source."""

    name = "glsl"

    @staticmethod
    def asfloat(*xs: Any) -> list[Expr]:
        return [_as_expr(x) for x in xs]

    @staticmethod
    def where(c: Any, a: Any, b: Any) -> Expr:
        c, a, b = _as_expr(c), _as_expr(a), _as_expr(b)
        size = max(a.size, b.size)
        if c.size == 1:
            return _node("({0} ? {1} : {2})", size, (c, _widen(a, size), _widen(b, size)), boolean=a.boolean)
        if c.size != size and size != 1:
            raise TypeError(f"cannot select {a.type} with a {c.type}")
        size = c.size
        # mix(b, a, c) takes a where c is true, componentwise (GLSL 3.30, GLSL ES 3.00).
        return _node("mix({2}, {1}, {0})", size, (c, _widen(a, size), _widen(b, size)))

    @staticmethod
    def clip(x: Any, lo: Any, hi: Any) -> Expr:
        x = _as_expr(x)
        return _call("clamp", x.size, x, lo, hi)

    @staticmethod
    def minimum(a: Any, b: Any) -> Expr:
        a, b = _as_expr(a), _as_expr(b)
        return _call("min", _broadcast(a, b), a, b) if a.size >= b.size else _call("min", b.size, b, a)

    @staticmethod
    def maximum(a: Any, b: Any) -> Expr:
        a, b = _as_expr(a), _as_expr(b)
        return _call("max", _broadcast(a, b), a, b) if a.size >= b.size else _call("max", b.size, b, a)

    @staticmethod
    def exp(x: Any) -> Expr:
        x = _as_expr(x)
        return _call("exp", x.size, x)

    @staticmethod
    def expm1(x: Any) -> Expr:
        # GLSL has no expm1; where the model uses it, |x| >= 1 and exp(x) - 1 loses nothing.
        x = _as_expr(x)
        return _call("exp", x.size, x) - 1.0

    @staticmethod
    def log(x: Any) -> Expr:
        x = _as_expr(x)
        return _call("log", x.size, x)

    @staticmethod
    def sqrt(x: Any) -> Expr:
        x = _as_expr(x)
        return _call("sqrt", x.size, x)

    @staticmethod
    def abs(x: Any) -> Expr:
        x = _as_expr(x)
        return _call("abs", x.size, x)

    @staticmethod
    def floor(x: Any) -> Expr:
        x = _as_expr(x)
        return _call("floor", x.size, x)

    @staticmethod
    def sin(x: Any) -> Expr:
        x = _as_expr(x)
        return _call("sin", x.size, x)

    @staticmethod
    def cos(x: Any) -> Expr:
        x = _as_expr(x)
        return _call("cos", x.size, x)

    @staticmethod
    def power(x: Any, p: Any) -> Expr:
        x = _as_expr(x)
        return _call("pow", x.size, x, _widen(_as_expr(p), x.size))

    @staticmethod
    def dot(a: Any, b: Any, keepdims: bool = False) -> Expr:
        a, b = _as_expr(a), _as_expr(b)
        return _call("dot", 1, a, b)

    @staticmethod
    def expand(x: Any) -> Expr:
        return _as_expr(x)

    @staticmethod
    def logical_and(a: Any, b: Any) -> Expr:
        a, b = _as_expr(a), _as_expr(b)
        if a.size != 1 or b.size != 1:
            raise TypeError("GLSL has no componentwise && for boolean vectors")
        return _node("({0} && {1})", 1, (a, b), boolean=True)

    @staticmethod
    def logical_or(a: Any, b: Any) -> Expr:
        a, b = _as_expr(a), _as_expr(b)
        if a.size != 1 or b.size != 1:
            raise TypeError("GLSL has no componentwise || for boolean vectors")
        return _node("({0} || {1})", 1, (a, b), boolean=True)

    @staticmethod
    def stack(xs: Sequence[Any]) -> Expr:
        xs = [_as_expr(x) for x in xs]
        if not 2 <= len(xs) <= 4 or any(x.size != 1 for x in xs):
            raise TypeError("a GLSL vector stacks 2 to 4 floats")
        return _call(f"vec{len(xs)}", len(xs), *xs)

    @staticmethod
    def call(name: str, size: int, *args: Any) -> Expr:
        """A call of a GLSL function that is not traced (a texture lookup a shader defines by hand): its result."""
        return _call(name, size, *args)


GLSL = _Glsl()


def namespace(*args: Any) -> Any:
    """`GLSL` if any argument (or a leaf of one) is symbolic, else `JAX`."""
    for a in args:
        if isinstance(a, Expr):
            return GLSL
        if isinstance(a, (tuple, list)) and any(isinstance(x, Expr) for x in a):
            return GLSL
    return JAX


# --- tracing into GLSL functions -------------------------------------------------------------------


@dataclass
class _Session:
    """The GLSL functions generated so far, in dependency order."""

    functions: dict[str, str] = field(default_factory=dict)


_session: list[_Session] = []


@contextlib.contextmanager
def glsl_session() -> Iterator[_Session]:
    """Collect the GLSL functions that traced `shader_function`s call."""
    s = _Session()
    _session.append(s)
    _memo.clear()
    try:
        yield s
    finally:
        _session.pop()
        _memo.clear()


def shader_function(name: str, arrays: Sequence[tuple[str, str]], returns: Sequence[tuple[str, str]] | str):
    """Mark a model function as a GLSL function of its own when traced.

    **Arguments:**

    - `name`: the GLSL function's name.
    - `arrays`: `(argument name, GLSL type)` of the function's array arguments,
      in the GLSL function's order. Its other arguments are compile-time
      constants (for example a `Params` whose leaves are uniforms): the same
      at every traced call.
    - `returns`: the GLSL return type, or `(name, type)` pairs for several
      results (written as `out` parameters).

    Called with JAX arrays, the function runs as written. Called with `Expr`s
    inside a `glsl_session`, its GLSL definition is generated once (its
    dependencies first) and the call becomes a GLSL call.
    """

    def decorate(fn: Callable) -> Callable:
        signature = inspect.signature(fn)

        @functools.wraps(fn)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            bound = signature.bind(*args, **kwargs)
            actual = [bound.arguments[a] for a, _ in arrays]
            if namespace(*actual) is JAX or not _session:
                return fn(*args, **kwargs)
            session = _session[-1]
            if name not in session.functions:

                def body(*symbols: Expr) -> Any:
                    b = signature.bind(*args, **kwargs)
                    b.arguments.update({a: x for (a, _), x in zip(arrays, symbols)})
                    return fn(*b.args, **b.kwargs)

                session.functions[name] = ""  # reserve: dependencies traced inside are defined before it
                source = _comment(fn) + trace_function(name, body, arrays, returns)
                del session.functions[name]
                session.functions[name] = source
            inputs = []
            for (a, t), x in zip(arrays, actual):
                x = _as_expr(x)
                if x.size != _size(t) and x.size != 1:
                    raise TypeError(f"{name}: {a} must be a {t}, got a {x.type}")
                inputs.append(_widen(x, _size(t)))
            if isinstance(returns, str):
                return _call(name, _size(returns), *inputs)
            # Several results: declared by the caller and passed as out parameters.
            k = next(_out_counter)
            outs = [Expr(f"{r}_{k}", _size(t), atom=True, out=True) for r, t in returns]
            slots = ", ".join(f"{{{i}}}" for i in range(len(inputs) + len(outs)))
            call = _node(f"{name}({slots})", 0, (*inputs, *outs))
            return tuple(Expr(o.code, o.size, args=(call,)) for o in outs)

        wrapper.glsl_name = name
        return wrapper

    return decorate


_out_counter = itertools.count()


def _comment(fn: Callable) -> str:
    """A GLSL comment naming the Python function a generated one comes from, with its summary."""
    summary = (fn.__doc__ or "").strip().split("\n")[0].replace("`", "")
    return f"// {summary}\n// Generated from {fn.__module__}.{fn.__qualname__}.\n"


def _size(glsl_type: str) -> int:
    return 1 if glsl_type in ("float", "bool") else int(glsl_type[-1])


def trace_function(
    name: str,
    fn: Callable,
    params: Sequence[tuple[str, str]],
    returns: Sequence[tuple[str, str]] | str,
) -> str:
    """GLSL source of a function `name` whose body is `fn` traced on symbolic parameters."""
    args = [Expr(p, _size(t), t.startswith("b") or t == "bool", atom=True) for p, t in params]
    result = fn(*args)
    sig = ", ".join(f"{t} {p}" for p, t in params)
    if isinstance(returns, str):
        body, (value,) = _emit([_as_expr(result)])
        return f"{returns} {name}({sig}) {{\n{body}    return {value};\n}}\n"
    results = [_as_expr(r) for r in result]
    body, values = _emit(results)
    outs = ", ".join(f"out {t} {r}" for r, t in returns)
    assigns = "".join(f"    {r} = {v};\n" for (r, _), v in zip(returns, values))
    return f"void {name}({sig}, {outs}) {{\n{body}{assigns}}}\n"


def _emit(results: list[Expr]) -> tuple[str, list[str]]:
    """Statements (calls with out parameters, and locals for sub-expressions used more than once) and the results' source."""
    uses: dict[int, int] = {}
    order: list[Expr] = []
    seen: set[int] = set()

    def visit(e: Expr) -> None:
        if e.id in seen:
            return
        seen.add(e.id)
        for a in e.args:
            uses[a.id] = uses.get(a.id, 0) + 1
            visit(a)
        order.append(e)

    for r in results:
        visit(r)
    names: dict[int, str] = {}

    def text(e: Expr) -> str:
        if e.id in names:
            return names[e.id]
        if e.atom:
            return e.code
        # Arguments of calls and of a parenthesised ternary need no parentheses; operands of an
        # operator do where they bind less tightly, and right operands of equal precedence keep
        # theirs (float rounding follows the evaluation order: a + (b + c) is not (a + b) + c).
        delimited = e.code.startswith("(") or (e.code[0].isalpha() and not e.code.startswith("{"))
        parts = []
        for i, a in enumerate(e.args):
            t = text(a)
            p = 9 if a.id in names else a.prec
            if not delimited and (p < e.prec or (p == e.prec and i > 0 and e.prec < 9)):
                t = f"({t})"
            parts.append(t)
        return e.code.format(*parts)

    lines: list[str] = []
    counter = itertools.count()
    for e in order:
        if e.atom:
            continue
        if e.size == 0:  # a call with out parameters: declare the outs, then the call as a statement
            lines += [f"    {o.type} {o.code};" for o in e.args if o.out]
            lines.append(f"    {text(e)};")
        elif e.args and e.args[0].size == 0:  # an out parameter of such a call
            names[e.id] = e.code
        elif uses.get(e.id, 0) > 1:
            local = f"t{next(counter)}"
            lines.append(f"    {e.type} {local} = {text(e)};")
            names[e.id] = local
    return "".join(line + "\n" for line in lines), [text(r) for r in results]
