"""Translate Warp functions to OpenCL C, so that the physics exists in one place only.

The random walk, the BSDFs, the samplers and the random number generator are written once, as
Warp functions (:mod:`.physics`, :mod:`.sampling`, :mod:`.rng`, :mod:`.walk`). The OpenCL backend
of the Monte Carlo reference does not re-implement them: this module reads each function's Python
source (``inspect.getsource`` of the function behind the ``wp.func``), walks its ``ast`` and emits
the equivalent OpenCL C, specialised to the concrete argument types of each call site, exactly as
Warp specialises generic (``typing.Any``) functions for CUDA and the CPU.

Supported subset (what the translated modules use; anything else raises :class:`CodegenError`
naming the function and line):

* arguments annotated with Warp scalar types (``wp.float32``, ``wp.float64``, ``int``,
  ``wp.uint32``, ``wp.int64``, ``wp.uint64``, ``bool``), ``wp.vec3``/``wp.vec3d``,
  ``wp.array(dtype=scalar)`` (1-D, ``__global`` pointers) or ``typing.Any`` (generic: the type is
  taken from the call site);
* assignments (declarations are hoisted, a variable keeps the type of its first assignment),
  augmented assignments, tuple unpacking of calls, ``if``/``elif``/``else``, ``while``,
  ``for ... in range(...)`` (positive constant step), ``break``, ``continue``, ``return`` of one or
  several values (several values become out-pointer parameters);
* arithmetic, comparisons, ``and``/``or``/``not``, bit operations, vec3 arithmetic with scalars,
  constant indexing of vectors (``v[0]`` -> ``v.x``), array indexing;
* ``type(x)(c)`` casts and vector constructors, ``wp.vector``, ``wp.vec3``, scalar type casts,
  ``int()``/``float()``, and the builtins in :data:`_MATH` plus ``abs``, ``min``, ``max``,
  ``clamp``, ``dot``, ``cross``, ``length``, ``normalize``, ``atomic_add`` (integers only);
* module-level constants (``wp.constant``) and ``wp.pi``; constant sub-expressions are folded in
  double precision before being rounded to the target type;
* closures (functions built inside a Python function see its captured variables) and
  ``wp.static(expr)``, evaluated at translation as Warp evaluates it at code generation: an
  ``if wp.static(...)`` emits only the branch taken.

Literals follow Warp: an untyped float literal is ``float`` (float32), an untyped integer ``int``;
a literal combined with a typed operand takes that operand's type.

Precision: generic functions are specialised for whatever the caller passes. The walk is float32
by design (``float`` in OpenCL); the translator tests also instantiate the physics in ``double``
where the device reports ``cl_khr_fp64``, and the ``#pragma`` enabling it is emitted only then.

Example::

    prog = Program()
    prog.add_kernel(walk.walk_thread, name="walk")     # kernel wrapper around a typed function
    source = prog.source()
"""

from __future__ import annotations

import ast
import builtins
import functools
import inspect
import math
import textwrap
import typing
from dataclasses import dataclass, field

import numpy as np
import warp as wp

__all__ = ["CodegenError", "Program", "opencl_type", "parameters"]


class CodegenError(Exception):
    """A Warp function uses a construct outside the translated subset."""


# ------------------------------------------------------------------------------------------------
# Types: OpenCL spellings; pointers are "T*"; literals without a type yet are weak.
# ------------------------------------------------------------------------------------------------

WEAK_FLOAT = "weak float"
WEAK_INT = "weak int"
_FLOATS = ("float", "double")
_INTS = ("int", "uint", "long", "ulong")
_VEC = {"float3": "float", "double3": "double"}
_VEC_OF = {v: k for k, v in _VEC.items()}
_BITS = {"int": 32, "uint": 32, "long": 64, "ulong": 64}

_WARP_SCALARS = {
    wp.float32: "float", wp.float64: "double", wp.int32: "int", wp.uint32: "uint",
    wp.int64: "long", wp.uint64: "ulong", wp.bool: "bool",
    float: "float", int: "int", bool: "bool",
}
_WARP_VECTORS = {wp.vec3f: "float3", wp.vec3d: "double3"}

_MATH = ("sqrt", "exp", "log", "erf", "erfc", "cos", "sin", "tan", "acos", "asin", "atan",
         "atan2", "floor", "ceil", "round")

# Names that must not be used for C identifiers (C/OpenCL keywords, types, builtins we emit).
_RESERVED = {
    "auto", "break", "case", "char", "const", "continue", "default", "do", "double", "else",
    "enum", "extern", "float", "for", "goto", "if", "inline", "int", "long", "register",
    "restrict", "return", "short", "signed", "sizeof", "static", "struct", "switch", "typedef",
    "union", "unsigned", "void", "volatile", "while", "bool", "true", "false", "half", "uint",
    "ulong", "uchar", "ushort", "size_t", "kernel", "global", "local", "constant", "private",
    "generic", "read_only", "write_only", "read_write", "vector", "image2d_t", "sampler_t",
    "event_t", "float3", "double3", "fabs", "fmin", "fmax", "abs", "min", "max", "clamp", "dot",
    "cross", "length", "normalize", "atom_add", "atomic_add", "get_global_id", "select", "sign",
    "step", "mix", "pow", "rint", "trunc", "fmod",
} | set(_MATH)


def opencl_type(warp_type) -> str:
    """OpenCL spelling of a Warp annotation (scalar, vec3, 1-D array); raises for others."""
    if warp_type in _WARP_SCALARS:
        return _WARP_SCALARS[warp_type]
    if warp_type in _WARP_VECTORS:
        return _WARP_VECTORS[warp_type]
    if isinstance(warp_type, wp.array):
        if warp_type.ndim != 1 or warp_type.dtype not in _WARP_SCALARS:
            raise CodegenError(f"only 1-D arrays of scalars are translated, got {warp_type}")
        return _WARP_SCALARS[warp_type.dtype] + "*"
    raise CodegenError(f"no OpenCL equivalent for the Warp type {warp_type!r}")


def _is_ptr(t: str) -> bool:
    return t.endswith("*")


def _strong(t: str) -> str:
    """Default type of a weak literal (Warp: float32 / int32)."""
    return {"weak float": "float", "weak int": "int"}.get(t, t)


def _literal(value, t: str) -> str:
    """C literal of the Python number ``value`` as type ``t``."""
    if t == "bool":
        return "true" if value else "false"
    if t in _FLOATS:
        v = float(value)
        if not math.isfinite(v):
            raise CodegenError(f"non-finite constant {value!r}")
        if t == "float":
            v = float(np.float32(v))
            return f"{v!r}f" if v >= 0 else f"(-{-v!r}f)"
        return repr(v) if v >= 0 else f"(-{-v!r})"
    if t in _INTS:
        if isinstance(value, float) and not value.is_integer():
            raise CodegenError(f"non-integer constant {value!r} used as {t}")
        v = int(value)
        bits = _BITS[t]
        if t.startswith("u"):
            v %= 1 << bits
        elif not -(1 << (bits - 1)) <= v < (1 << (bits - 1)):
            raise CodegenError(f"constant {value!r} does not fit in {t}")
        suffix = {"int": "", "uint": "u", "long": "L", "ulong": "UL"}[t]
        return f"{v}{suffix}" if v >= 0 else f"({v}{suffix})"
    raise CodegenError(f"cannot write a literal of type {t}")


@dataclass
class _Expr:
    code: str
    type: str
    value: object = None        # Python value for constants (folded)

    @property
    def weak(self) -> bool:
        return self.type in (WEAK_FLOAT, WEAK_INT)


def _as(e: _Expr, t: str, where: str) -> _Expr:
    """``e`` as type ``t``: weak literals are re-spelled, strong types must match."""
    if e.type == t:
        return e
    if e.weak and (t in _FLOATS or t in _INTS or t == "bool"):
        if e.type == WEAK_FLOAT and t in _INTS:
            raise CodegenError(f"{where}: float literal {e.value!r} used as {t}")
        return _Expr(_literal(e.value, t), t, e.value)
    raise CodegenError(f"{where}: expected {t}, got {e.type} ({e.code})")


def _unify(a: _Expr, b: _Expr, where: str) -> str:
    """Common type of a binary operation's scalar operands (Warp: identical types)."""
    if a.weak and b.weak:
        return WEAK_FLOAT if WEAK_FLOAT in (a.type, b.type) else WEAK_INT
    if a.weak:
        return b.type
    if b.weak:
        return a.type
    if a.type != b.type:
        raise CodegenError(f"{where}: mixed types {a.type} and {b.type} (cast explicitly)")
    return a.type


# ------------------------------------------------------------------------------------------------
# Function instances
# ------------------------------------------------------------------------------------------------

_BINOPS = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Mod: "%",
           ast.BitXor: "^", ast.BitAnd: "&", ast.BitOr: "|", ast.LShift: "<<",
           ast.RShift: ">>", ast.FloorDiv: "/"}
_PYOPS = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b,
          ast.Mult: lambda a, b: a * b, ast.Div: lambda a, b: a / b}
_CMPOPS = {ast.Lt: "<", ast.LtE: "<=", ast.Gt: ">", ast.GtE: ">=", ast.Eq: "==", ast.NotEq: "!="}


@dataclass
class _Instance:
    """One specialisation of a Warp function for concrete argument types."""
    name: str
    params: list            # [(c_name, type)]
    returns: list | None = None
    body: list = field(default_factory=list)
    decls: dict = field(default_factory=dict)

    def definition(self) -> str:
        args = [_param_decl(t, n) for n, t in self.params]
        if self.returns is None or len(self.returns) == 0:
            ret = "void"
        elif len(self.returns) == 1:
            ret = self.returns[0]
        else:
            ret = "void"
            args += [f"{t}* __out{i}" for i, t in enumerate(self.returns)]
        lines = [f"{ret} {self.name}({', '.join(args) or 'void'})", "{"]
        lines += [f"    {t} {n};" for n, t in self.decls.items()]
        lines += self.body
        lines.append("}")
        return "\n".join(lines)


def _one_group(code: str) -> bool:
    """True if ``code`` is a single parenthesised group ``( ... )``."""
    if not code.startswith("("):
        return False
    depth = 0
    for i, ch in enumerate(code):
        depth += (ch == "(") - (ch == ")")
        if depth == 0:
            return i == len(code) - 1
    return False


def _param_decl(t: str, name: str) -> str:
    if _is_ptr(t):
        return f"__global {t[:-1]}* {name}"
    return f"{t} {name}"


def _c_name(name: str) -> str:
    return name + "_" if name in _RESERVED or name.startswith("__") else name


def _type_code(t: str) -> str:
    codes = {"float": "f", "double": "d", "int": "i", "uint": "u", "long": "l", "ulong": "m",
             "bool": "b", "float3": "f3", "double3": "d3"}
    return ("p" + codes[t[:-1]]) if _is_ptr(t) else codes[t]


class Program:
    """A set of translated functions and kernel wrappers, emitted as one OpenCL C source."""

    def __init__(self):
        self._instances: dict = {}          # (pyfunc, argtypes) -> _Instance
        self._order: list = []              # definitions in dependency order
        self._in_progress: set = set()
        self._kernels: list = []
        self._names: dict = {}              # C name -> the Python functions that bear it
        self.uses_double = False
        self.uses_atomics64 = False

    # ---- public ---------------------------------------------------------------------------

    def add_function(self, func, argtypes) -> str:
        """Translate ``func`` (a ``wp.func``) for the OpenCL types ``argtypes``; returns its C
        name (its return types are in :meth:`returns`)."""
        return self._instantiate(func, tuple(argtypes)).name

    def returns(self, func, argtypes) -> list:
        return list(self._instantiate(func, tuple(argtypes)).returns or [])

    def add_kernel(self, func, name: str | None = None) -> str:
        """Emit ``__kernel void name(...)`` calling the fully typed ``func`` whose first
        parameter is the thread index (``int``, from ``get_global_id(0)``); the other parameters
        become the kernel arguments."""
        params = parameters(func)
        if not params or params[0][1] != "int":
            raise CodegenError(f"{func.key}: a kernel entry takes the thread index (int) first")
        types = [t for _, t in params]
        if any(t is None for t in types):
            raise CodegenError(f"{func.key}: a kernel entry must be fully typed (no Any)")
        if any(t == "bool" for t in types):
            raise CodegenError(f"{func.key}: bool is not a valid OpenCL kernel argument")
        inst = self._instantiate(func, tuple(types))
        if inst.returns:
            raise CodegenError(f"{func.key}: a kernel entry must not return values")
        kname = name or func.key
        args = [_param_decl(t, _c_name(n)) for n, t in params[1:]]
        call = ", ".join(["(int)get_global_id(0)"] + [_c_name(n) for n, _ in params[1:]])
        self._kernels.append(f"__kernel void {kname}({', '.join(args)})\n{{\n"
                             f"    {inst.name}({call});\n}}")
        return kname

    def add_map(self, func, argtypes, name: str) -> list:
        """Emit an elementwise kernel ``name`` applying ``func`` (specialised for ``argtypes``)
        to arrays: argument ``i`` is read from ``__global const T* a{i}`` (a vec3 as three
        consecutive scalars), result ``j`` is written to ``__global T* r{j}`` (bool as int).
        Used to compare translated functions with their Warp originals. Returns the result
        types."""
        argtypes = tuple(argtypes)
        inst = self._instantiate(func, argtypes)
        params, loads = [], []
        for i, t in enumerate(argtypes):
            if _is_ptr(t) or t == "bool":
                raise CodegenError(f"add_map: argument type {t} is not mappable")
            params.append(f"__global const {_VEC.get(t, t)}* a{i}")
            loads.append(f"vload3(gid, a{i})" if t in _VEC else f"a{i}[gid]")
        rets = list(inst.returns or [])
        body = ["    const int gid = (int)get_global_id(0);"]
        body += [f"    {t} v{j};" for j, t in enumerate(rets)]
        if len(rets) == 1:
            body.append(f"    v0 = {inst.name}({', '.join(loads)});")
        else:
            body.append(f"    {inst.name}({', '.join(loads + [f'&v{j}' for j in range(len(rets))])});")
        for j, t in enumerate(rets):
            params.append(f"__global {_VEC.get(t, 'int' if t == 'bool' else t)}* r{j}")
            body.append(f"    vstore3(v{j}, gid, r{j});" if t in _VEC else
                        f"    r{j}[gid] = {'(int)' if t == 'bool' else ''}v{j};")
        self._kernels.append(f"__kernel void {name}({', '.join(params)})\n{{\n"
                             + "\n".join(body) + "\n}")
        return rets

    def source(self) -> str:
        head = ["// Generated by layersim.kernels.opencl_codegen from the Warp functions of",
                "// layersim.kernels; do not edit."]
        if self.uses_double:
            head.append("#pragma OPENCL EXTENSION cl_khr_fp64 : enable")
        if self.uses_atomics64:
            head.append("#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable")
        return "\n".join(head) + "\n\n" + "\n\n".join(
            [i.definition() for i in self._order] + self._kernels) + "\n"

    # ---- instantiation --------------------------------------------------------------------

    def _instantiate(self, func, argtypes: tuple) -> _Instance:
        pyfunc = _python_function(func)
        key = (pyfunc, argtypes)
        if key in self._instances:
            return self._instances[key]
        if key in self._in_progress:
            raise CodegenError(f"{pyfunc.__name__}: recursion is not supported")
        params = parameters(func)
        if len(params) != len(argtypes):
            raise CodegenError(f"{pyfunc.__name__}: expected {len(params)} arguments, got "
                               f"{len(argtypes)}")
        generic = False
        typed = []
        for (pname, ptype), atype in zip(params, argtypes):
            if ptype is None:
                generic = True
                ptype = atype
            elif ptype != atype:
                raise CodegenError(f"{pyfunc.__name__}: argument '{pname}' is {ptype}, "
                                   f"called with {atype}")
            typed.append((pname, ptype))
        module = pyfunc.__module__.rsplit(".", 1)[-1]
        cname = f"ls_{module}_{pyfunc.__name__}"
        if generic:
            cname += "_" + "".join(_type_code(t) for t in argtypes)
        # closures of one name (walks built for different features) get distinct C names
        taken = self._names.setdefault(cname, [])
        if pyfunc not in taken:
            taken.append(pyfunc)
        if taken.index(pyfunc):
            cname += f"_v{taken.index(pyfunc)}"
        inst = _Instance(cname, [(_c_name(n), t) for n, t in typed])
        self._in_progress.add(key)
        try:
            _FunctionTranslator(self, pyfunc, inst, dict(typed)).run()
        finally:
            self._in_progress.discard(key)
        if any(t in ("double", "double3") for _, t in inst.params) or any(
                t in ("double", "double3") for t in inst.decls.values()):
            self.uses_double = True
        self._instances[key] = inst
        self._order.append(inst)
        return inst


#: What :meth:`_FunctionTranslator.static_value` returns for an expression that is not
#: ``wp.static(...)``.
_NOT_STATIC = object()


@dataclass(frozen=True)
class _KernelOnlyBuiltin:
    """A Warp builtin that exists only inside kernels (``wp.vector``, ...): it is not an
    attribute of the ``warp`` module, so it is known here by its name alone, and
    :meth:`_Translator.builtin` decides whether it has an OpenCL translation."""

    key: str

    def is_builtin(self) -> bool:
        return True


def _python_function(func):
    pyfunc = getattr(func, "func", None)
    if pyfunc is None or not callable(pyfunc) or getattr(func, "is_builtin", lambda: True)():
        raise CodegenError(f"{func!r} is not a user-defined Warp function")
    return pyfunc


@functools.lru_cache(maxsize=None)
def _function_ast(pyfunc) -> ast.FunctionDef:
    src = textwrap.dedent(inspect.getsource(pyfunc))
    tree = ast.parse(src)
    fdef = tree.body[0]
    if not isinstance(fdef, ast.FunctionDef):
        raise CodegenError(f"{pyfunc.__name__}: expected a function definition")
    return fdef


def _scope(pyfunc) -> dict:
    """The names a function's body sees: its module's globals and, for a closure, the
    variables it captures (a walk built for a set of features captures them)."""
    scope = dict(pyfunc.__globals__)
    if pyfunc.__closure__:
        scope.update((name, cell.cell_contents) for name, cell in
                     zip(pyfunc.__code__.co_freevars, pyfunc.__closure__))
    return scope


def parameters(func) -> list:
    """``[(name, OpenCL type or None for Any)]`` of a Warp function, from its annotations."""
    return list(_annotations_of(_python_function(func)))


@functools.lru_cache(maxsize=None)
def _annotations_of(pyfunc) -> tuple:
    fdef = _function_ast(pyfunc)
    out = []
    for arg in fdef.args.args:
        if arg.annotation is None:
            raise CodegenError(f"{pyfunc.__name__}: argument '{arg.arg}' needs an annotation")
        ann = eval(compile(ast.Expression(arg.annotation), "<annotation>", "eval"),
                   _scope(pyfunc))
        out.append((arg.arg, None if ann is typing.Any else opencl_type(ann)))
    return tuple(out)


class _FunctionTranslator:
    """Emits the body of one function instance."""

    def __init__(self, program: Program, pyfunc, inst: _Instance, params: dict):
        self.prog = program
        self.pyfunc = pyfunc
        self.inst = inst
        self.types = dict(params)           # python name -> type
        self.params = set(params)
        self.globals = _scope(pyfunc)
        self.fdef = _function_ast(pyfunc)
        self.first_line = inspect.getsourcelines(pyfunc)[1]
        self.lineno = self.first_line

    # ---- helpers --------------------------------------------------------------------------

    def where(self) -> str:
        return f"{self.pyfunc.__module__}.{self.pyfunc.__name__} (line {self.lineno})"

    def fail(self, msg: str):
        raise CodegenError(f"{self.where()}: {msg}")

    def declare(self, name: str, t: str) -> str:
        t = _strong(t)
        if name in self.types:
            if self.types[name] != t:
                self.fail(f"variable '{name}' changes type from {self.types[name]} to {t}")
        else:
            if _is_ptr(t):
                self.fail(f"cannot bind an array to the local name '{name}'")
            self.types[name] = t
            self.inst.decls[_c_name(name)] = t
        return _c_name(name)

    def run(self):
        body = self.fdef.body
        if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
                and isinstance(body[0].value.value, str):
            body = body[1:]
        self.inst.body = self.block(body, 1)

    # ---- statements -----------------------------------------------------------------------

    def block(self, stmts, depth: int) -> list:
        out = []
        for st in stmts:
            out += self.stmt(st, depth)
        return out

    def stmt(self, st, depth: int) -> list:
        self.lineno = self.first_line + st.lineno - 1
        pad = "    " * depth
        if isinstance(st, ast.Assign):
            if len(st.targets) != 1:
                self.fail("chained assignment")
            return [pad + s for s in self.assign(st.targets[0], st.value)]
        if isinstance(st, ast.AugAssign):
            if not isinstance(st.target, ast.Name):
                self.fail("augmented assignment to a non-variable")
            value = ast.BinOp(left=ast.Name(id=st.target.id, ctx=ast.Load()), op=st.op,
                              right=st.value)
            return [pad + s for s in self.assign(st.target, value)]
        if isinstance(st, ast.If):
            static = self.static_value(st.test)
            if static is not _NOT_STATIC:      # wp.static(...): only the branch taken
                return self.block(st.body if static else st.orelse, depth)
            cond = self.cond(st.test)
            lines = [f"{pad}if ({cond}) {{"] + self.block(st.body, depth + 1)
            if st.orelse:
                lines += [f"{pad}}} else {{"] + self.block(st.orelse, depth + 1)
            return lines + [pad + "}"]
        if isinstance(st, ast.While):
            if st.orelse:
                self.fail("while/else")
            cond = self.cond(st.test)
            return [f"{pad}while ({cond}) {{"] + self.block(st.body, depth + 1) + [pad + "}"]
        if isinstance(st, ast.For):
            return self.for_range(st, depth)
        if isinstance(st, ast.Break):
            return [pad + "break;"]
        if isinstance(st, ast.Continue):
            return [pad + "continue;"]
        if isinstance(st, ast.Pass):
            return []
        if isinstance(st, ast.Return):
            return [pad + s for s in self.ret(st.value)]
        if isinstance(st, ast.Expr):
            if isinstance(st.value, ast.Constant) and isinstance(st.value.value, str):
                return []
            if not isinstance(st.value, ast.Call):
                self.fail("expression statement that is not a call")
            e = self.expr(st.value)
            return [f"{pad}{e.code};"]
        self.fail(f"unsupported statement {type(st).__name__}")

    def assign(self, target, value) -> list:
        if isinstance(target, ast.Name):
            e = self.expr(value)
            if e.type == "void" or isinstance(e.type, tuple):
                self.fail("assigning a call that does not return exactly one value")
            if target.id in self.types:
                old = self.types[target.id]
                if not e.weak and e.type != old:
                    self.fail(f"variable '{target.id}' changes type from {old} to {e.type}")
                e = _as(e, old, self.where())
            name = self.declare(target.id, e.type)
            return [f"{name} = {e.code};"]
        if isinstance(target, ast.Tuple):
            if not isinstance(value, ast.Call):
                self.fail("tuple assignment from something other than a call")
            call, rtypes, args = self.user_call(value)
            if len(rtypes) != len(target.elts):
                self.fail(f"unpacking {len(rtypes)} values into {len(target.elts)} names")
            outs = []
            for elt, t in zip(target.elts, rtypes):
                if not isinstance(elt, ast.Name):
                    self.fail("tuple targets must be plain names")
                outs.append("&" + self.declare(elt.id, t))
            return [f"{call}({', '.join(args + outs)});"]
        if isinstance(target, ast.Subscript):
            base = self.expr(target.value)
            if not _is_ptr(base.type):
                self.fail("item assignment is only translated for arrays")
            idx = self.index(target.slice)
            e = _as(self.expr(value), base.type[:-1], self.where())
            return [f"{base.code}[{idx}] = {e.code};"]
        self.fail(f"unsupported assignment target {type(target).__name__}")

    def for_range(self, st, depth: int) -> list:
        pad = "    " * depth
        if st.orelse or not isinstance(st.target, ast.Name):
            self.fail("only 'for name in range(...)' loops are translated")
        it = st.iter
        if not (isinstance(it, ast.Call) and isinstance(it.func, ast.Name)
                and it.func.id == "range" and 1 <= len(it.args) <= 3):
            self.fail("only 'for name in range(...)' loops are translated")
        args = [_as(self.expr(a), "int", self.where()) for a in it.args]
        start, stop, step = ("0", args[0].code, "1") if len(args) == 1 else (
            args[0].code, args[1].code, args[2].code if len(args) == 3 else "1")
        if len(args) == 3 and (args[2].value is None or args[2].value <= 0):
            self.fail("range() step must be a positive constant")
        var = self.declare(st.target.id, "int")
        return ([f"{pad}for ({var} = {start}; {var} < {stop}; {var} += {step}) {{"]
                + self.block(st.body, depth + 1) + [pad + "}"])

    def ret(self, value) -> list:
        if value is None:
            vals = []
        elif isinstance(value, ast.Tuple):
            vals = [self.expr(v) for v in value.elts]
        else:
            vals = [self.expr(value)]
        if self.inst.returns is None:
            self.inst.returns = [_strong(v.type) for v in vals]
        if len(vals) != len(self.inst.returns):
            self.fail("return statements return different numbers of values")
        vals = [_as(v, t, self.where()) for v, t in zip(vals, self.inst.returns)]
        if len(vals) == 0:
            return ["return;"]
        if len(vals) == 1:
            return [f"return {vals[0].code};"]
        return ["{ " + " ".join(f"*__out{i} = {v.code};" for i, v in enumerate(vals))
                + " return; }"]

    # ---- expressions ----------------------------------------------------------------------

    def static_value(self, node):
        """The value of ``wp.static(expr)``, evaluated in the function's scope as Warp does at
        code generation, or :data:`_NOT_STATIC` for any other expression."""
        if not (isinstance(node, ast.Call) and len(node.args) == 1 and not node.keywords
                and isinstance(node.func, ast.Attribute) and node.func.attr == "static"
                and isinstance(node.func.value, ast.Name)
                and self.globals.get(node.func.value.id) is wp):
            return _NOT_STATIC
        try:
            return eval(compile(ast.Expression(node.args[0]), "<wp.static>", "eval"),
                        self.globals)
        except Exception as exc:
            self.fail(f"wp.static({ast.unparse(node.args[0])}) cannot be evaluated: {exc}")

    def cond(self, node) -> str:
        """Condition code, parenthesised exactly once (for ``if (...)``/``while (...)``)."""
        e = self.expr(node)
        if e.type != "bool":
            self.fail(f"condition of type {e.type} (compare explicitly)")
        return e.code[1:-1] if _one_group(e.code) else e.code

    def index(self, node) -> str:
        e = self.expr(node)
        if not (e.weak or e.type in _INTS):
            self.fail(f"array index of type {e.type}")
        return _as(e, "int", self.where()).code if e.weak else e.code

    def resolve(self, node):
        """Python object named by a global Name/Attribute chain (modules, constants, funcs)."""
        if isinstance(node, ast.Name):
            if node.id in self.globals:
                return self.globals[node.id]
            if hasattr(builtins, node.id):
                return getattr(builtins, node.id)
            self.fail(f"unknown name '{node.id}'")
        if isinstance(node, ast.Attribute):
            base = self.resolve(node.value)
            if base is wp and not hasattr(wp, node.attr):
                return _KernelOnlyBuiltin(node.attr)
            return getattr(base, node.attr)
        self.fail(f"cannot resolve {ast.unparse(node)}")

    def constant(self, value) -> _Expr:
        if isinstance(value, bool):
            return _Expr(_literal(value, "bool"), "bool", value)
        if isinstance(value, int):
            return _Expr(_literal(value, "int"), WEAK_INT, value)
        if isinstance(value, float):
            return _Expr(_literal(value, "float"), WEAK_FLOAT, value)
        for wt, t in _WARP_SCALARS.items():
            if isinstance(wt, type) and isinstance(value, wt) and hasattr(value, "value"):
                return _Expr(_literal(value.value, t), t, None)
        self.fail(f"unsupported constant {value!r}")

    def expr(self, node) -> _Expr:
        if isinstance(node, ast.Constant):
            return self.constant(node.value)
        if isinstance(node, ast.Name):
            if node.id in self.types:
                return _Expr(_c_name(node.id), self.types[node.id])
            if node.id in ("True", "False"):
                return self.constant(node.id == "True")
            return self.constant(self.resolve(node))
        if isinstance(node, ast.Attribute):
            return self.constant(self.resolve(node))
        if isinstance(node, ast.BinOp):
            return self.binop(node)
        if isinstance(node, ast.UnaryOp):
            e = self.expr(node.operand)
            if isinstance(node.op, ast.USub):
                if e.value is not None and e.weak:
                    return self.constant(-e.value)
                return _Expr(f"(-{e.code})", e.type)
            if isinstance(node.op, ast.UAdd):
                return e
            if isinstance(node.op, ast.Not):
                if e.type != "bool":
                    self.fail("'not' of a non-bool")
                return _Expr(f"(!{e.code})", "bool")
            if isinstance(node.op, ast.Invert):
                if e.type not in _INTS:
                    self.fail("'~' of a non-integer")
                return _Expr(f"(~{e.code})", e.type)
        if isinstance(node, ast.BoolOp):
            op = " && " if isinstance(node.op, ast.And) else " || "
            parts = [self.expr(v) for v in node.values]
            if any(p.type != "bool" for p in parts):
                self.fail("and/or of non-bool operands")
            return _Expr("(" + op.join(p.code for p in parts) + ")", "bool")
        if isinstance(node, ast.Compare):
            parts = []
            left = node.left
            for op, right in zip(node.ops, node.comparators):
                if type(op) not in _CMPOPS:
                    self.fail(f"unsupported comparison {type(op).__name__}")
                a, b = self.expr(left), self.expr(right)
                t = _unify(a, b, self.where())
                if t in (WEAK_FLOAT, WEAK_INT):
                    t = _strong(t)
                a, b = _as(a, t, self.where()), _as(b, t, self.where())
                parts.append(f"({a.code} {_CMPOPS[type(op)]} {b.code})")
                left = right
            return _Expr(parts[0] if len(parts) == 1 else "(" + " && ".join(parts) + ")",
                         "bool")
        if isinstance(node, ast.Subscript):
            base = self.expr(node.value)
            if base.type in _VEC:
                i = self.expr(node.slice)
                if i.value not in (0, 1, 2) or not i.weak:
                    self.fail("vector components must be indexed with a constant 0, 1 or 2")
                return _Expr(f"{base.code}.{'xyz'[i.value]}", _VEC[base.type])
            if _is_ptr(base.type):
                return _Expr(f"{base.code}[{self.index(node.slice)}]", base.type[:-1])
            self.fail(f"indexing a value of type {base.type}")
        if isinstance(node, ast.Call):
            static = self.static_value(node)
            if static is not _NOT_STATIC:
                return self.constant(static)
            return self.call(node)
        self.fail(f"unsupported expression {type(node).__name__}")

    def binop(self, node) -> _Expr:
        if type(node.op) not in _BINOPS:
            self.fail(f"unsupported operator {type(node.op).__name__}")
        a, b = self.expr(node.left), self.expr(node.right)
        op = _BINOPS[type(node.op)]
        if a.weak and b.weak and a.value is not None and b.value is not None \
                and type(node.op) in _PYOPS:
            v = _PYOPS[type(node.op)](a.value, b.value)
            if isinstance(node.op, ast.Div) and a.type == WEAK_INT and b.type == WEAK_INT:
                self.fail("integer division of constants")
            return self.constant(v)
        for vec, sc in ((a, b), (b, a)):
            if vec.type in _VEC and sc.type not in _VEC:
                if op not in "*/" or (op == "/" and vec is b):
                    self.fail(f"vector {op} scalar")
                s = _as(sc, _VEC[vec.type], self.where())
                left, right = (vec, s) if vec is a else (s, vec)
                return _Expr(f"({left.code} {op} {right.code})", vec.type)
        if a.type in _VEC or b.type in _VEC:
            if a.type != b.type or op not in "+-":
                self.fail(f"vector operation {a.type} {op} {b.type}")
            return _Expr(f"({a.code} {op} {b.code})", a.type)
        t = _unify(a, b, self.where())
        if t in (WEAK_FLOAT, WEAK_INT):
            t = _strong(t)
        if op in ("^", "&", "|", "<<", ">>", "%") and t not in _INTS:
            self.fail(f"operator {op} on {t}")
        if isinstance(node.op, ast.FloorDiv) and t not in _INTS:
            self.fail("// on floats")
        a, b = _as(a, t, self.where()), _as(b, t, self.where())
        return _Expr(f"({a.code} {op} {b.code})", t)

    # ---- calls ----------------------------------------------------------------------------

    def call(self, node) -> _Expr:
        if node.keywords:
            self.fail("keyword arguments")
        f = node.func
        # type(x)(...)
        if isinstance(f, ast.Call) and isinstance(f.func, ast.Name) and f.func.id == "type":
            t = self.expr(f.args[0]).type
            if t in (WEAK_FLOAT, WEAK_INT):
                t = _strong(t)
            return self.construct(t, node.args)
        if isinstance(f, ast.Name) and f.id in ("int", "float", "bool") and f.id not in self.types:
            return self.construct({"int": "int", "float": "float", "bool": "bool"}[f.id],
                                  node.args)
        obj = self.resolve(f)
        if obj in _WARP_SCALARS or obj in _WARP_VECTORS:
            return self.construct(opencl_type(obj), node.args)
        if getattr(obj, "is_builtin", None) and obj.is_builtin():
            return self.builtin(obj.key, node.args)
        call, rtypes, args = self.user_call(node)
        if len(rtypes) != 1:
            if len(rtypes) == 0:
                return _Expr(f"{call}({', '.join(args)})", "void")
            self.fail(f"a call returning {len(rtypes)} values must be unpacked")
        return _Expr(f"{call}({', '.join(args)})", rtypes[0])

    def user_call(self, node):
        obj = self.resolve(node.func)
        params = parameters(obj)
        if len(params) != len(node.args):
            self.fail(f"{obj.key} takes {len(params)} arguments")
        args, types = [], []
        for (pname, ptype), a in zip(params, node.args):
            e = self.expr(a)
            t = ptype if ptype is not None else _strong(e.type)
            e = _as(e, t, self.where()) if not _is_ptr(t) else e
            if e.type != t:
                self.fail(f"argument '{pname}' of {obj.key}: expected {t}, got {e.type}")
            args.append(e.code)
            types.append(t)
        inst = self.prog._instantiate(obj, tuple(types))
        return inst.name, list(inst.returns or []), args

    def construct(self, t: str, args) -> _Expr:
        where = self.where()
        if t in _VEC:
            vals = [self.expr(a) for a in args]
            if len(vals) == 0:
                return _Expr(f"(({t})(0))", t)
            if len(vals) != 3:
                self.fail(f"{t} needs 3 components")
            vals = [_as(v, _VEC[t], where) for v in vals]
            return _Expr(f"(({t})({', '.join(v.code for v in vals)}))", t)
        if len(args) != 1:
            self.fail(f"cast to {t} takes one argument")
        e = self.expr(args[0])
        if e.value is not None and e.weak:
            return _Expr(_literal(e.value, t), t, None)
        if e.type == t:
            return e
        if e.type in _VEC or _is_ptr(e.type):
            self.fail(f"cannot cast {e.type} to {t}")
        return _Expr(f"(({t})({e.code}))", t)

    def builtin(self, name: str, args) -> _Expr:
        where = self.where()
        if name == "atomic_add":
            if len(args) != 3:
                self.fail("atomic_add(array, index, value)")
            arr = self.expr(args[0])
            if not _is_ptr(arr.type) or arr.type[:-1] not in _INTS:
                self.fail("atomic_add is translated for integer arrays only (deterministic)")
            elem = arr.type[:-1]
            v = _as(self.expr(args[2]), elem, where)
            fn = "atom_add" if _BITS[elem] == 64 else "atomic_add"
            if _BITS[elem] == 64:
                self.prog.uses_atomics64 = True
            return _Expr(f"{fn}(&{arr.code}[{self.index(args[1])}], {v.code})", elem)
        if name == "vector":
            vals = [self.expr(a) for a in args]
            strong = {v.type for v in vals if not v.weak}
            if len(vals) != 3 or len(strong) > 1:
                self.fail("wp.vector takes 3 components of one scalar type")
            elem = strong.pop() if strong else "float"
            if elem not in _FLOATS:
                self.fail(f"vectors of {elem}")
            return self.construct(_VEC_OF[elem], args)
        vals = [self.expr(a) for a in args]
        if name in ("dot", "cross", "length", "normalize"):
            if any(v.type not in _VEC for v in vals) or len({v.type for v in vals}) != 1:
                self.fail(f"{name} of {[v.type for v in vals]}")
            t = vals[0].type
            rt = _VEC[t] if name in ("dot", "length") else t
            return _Expr(f"{name}({', '.join(v.code for v in vals)})", rt)
        # scalar builtins: operands share one type (literals adopt it)
        strong = [v.type for v in vals if not v.weak]
        if strong:
            t = strong[0]
        else:
            t = "float" if any(v.type == WEAK_FLOAT for v in vals) else "int"
        vals = [_as(v, t, where) for v in vals]
        codes = ", ".join(v.code for v in vals)
        if name in _MATH:
            if t not in _FLOATS:
                self.fail(f"{name} of {t}")
            return _Expr(f"{name}({codes})", t)
        if name == "abs":
            if t in _FLOATS:
                return _Expr(f"fabs({codes})", t)
            return _Expr(f"(({t})abs({codes}))", t)
        if name in ("min", "max"):
            fn = ("f" + name) if t in _FLOATS else name
            return _Expr(f"{fn}({codes})", t)
        if name == "clamp":
            return _Expr(f"clamp({codes})", t)
        self.fail(f"builtin wp.{name} is not translated")
