"""Test helper: evaluate Warp functions elementwise on Warp and, translated, on OpenCL.

``ProbeSet`` takes cases ``(func, argtypes)`` (OpenCL spellings: "float", "double3", ...) and
builds, once per test session, one Warp module with an elementwise kernel per case (generated
Python source, imported from a temporary file) and one OpenCL program (``Program.add_map``).
Inputs are numpy arrays: shape (N,) for scalars, (N, 3) for vec3.
"""

from __future__ import annotations

import importlib.util
import sys

import numpy as np
import warp as wp

from layersim.kernels.opencl_codegen import Program
from layersim.kernels.runtime import ensure_init

_WARP = {"float": "wp.float32", "double": "wp.float64", "int": "wp.int32", "uint": "wp.uint32",
         "long": "wp.int64", "ulong": "wp.uint64", "float3": "wp.vec3f", "double3": "wp.vec3d",
         "bool": "wp.int32"}
_NP = {"float": np.float32, "double": np.float64, "int": np.int32, "uint": np.uint32,
       "long": np.int64, "ulong": np.uint64, "float3": np.float32, "double3": np.float64,
       "bool": np.int32}


def _ref(func) -> tuple[str, str]:
    """(module, attribute) under which the Warp function is importable."""
    mod = func.func.__module__
    return mod, func.func.__name__


class ProbeSet:
    def __init__(self, cases, tmpdir, cl_device=None, name="layersim_test_probes"):
        ensure_init()
        self.cases = [(f, tuple(t)) for f, t in cases]
        self.prog = Program()
        self.rets = [self.prog.add_map(f, t, f"probe{i}") for i, (f, t) in
                     enumerate(self.cases)]
        self._warp = self._build_warp(tmpdir, name)
        self._cl = None
        self.cl_device = cl_device

    # ---- Warp -----------------------------------------------------------------------------

    def _build_warp(self, tmpdir, name):
        lines = ["import warp as wp", "wp.set_module_options({'enable_backward': False})"]
        mods = sorted({_ref(f)[0] for f, _ in self.cases})
        lines += [f"import {m}" for m in mods]
        for i, ((f, types), rets) in enumerate(zip(self.cases, self.rets)):
            mod, fname = _ref(f)
            args = [f"a{j}: wp.array(dtype={_WARP[t]})" for j, t in enumerate(types)]
            args += [f"r{j}: wp.array(dtype={_WARP[t]})" for j, t in enumerate(rets)]
            vals = ", ".join(f"v{j}" for j in range(len(rets)))
            call = f"{mod}.{fname}(" + ", ".join(f"a{j}[i]" for j in range(len(types))) + ")"
            lines += ["", "@wp.kernel", f"def probe{i}({', '.join(args)}):", "    i = wp.tid()",
                      f"    {vals} = {call}"]
            for j, t in enumerate(rets):
                if t == "bool":
                    lines += [f"    if v{j}:", f"        r{j}[i] = 1", "    else:",
                              f"        r{j}[i] = 0"]
                else:
                    lines.append(f"    r{j}[i] = v{j}")
        path = tmpdir / f"{name}.py"
        path.write_text("\n".join(lines) + "\n")
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
        return module

    def warp(self, i: int, *inputs):
        """Outputs of case ``i`` evaluated by Warp on the CPU."""
        types = self.cases[i][1]
        arrays = [wp.array(np.asarray(x, dtype=_NP[t]), dtype=eval(_WARP[t]))
                  for x, t in zip(inputs, types)]
        n = len(inputs[0])
        outs = [wp.zeros(n, dtype=eval(_WARP[t])) for t in self.rets[i]]
        wp.launch(getattr(self._warp, f"probe{i}"), dim=n, inputs=arrays + outs)
        return [o.numpy() for o in outs]

    # ---- OpenCL ---------------------------------------------------------------------------

    def _build_cl(self):
        import pyopencl as cl
        ctx = cl.Context([self.cl_device])
        queue = cl.CommandQueue(ctx)
        program = cl.Program(ctx, self.prog.source()).build()
        self._cl = (cl, ctx, queue, program)

    def opencl(self, i: int, *inputs):
        """Outputs of case ``i`` evaluated by the translated OpenCL C."""
        if self._cl is None:
            self._build_cl()
        cl, ctx, queue, program = self._cl
        types = self.cases[i][1]
        mf = cl.mem_flags
        n = len(inputs[0])
        bufs = [cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR,
                          hostbuf=np.ascontiguousarray(x, dtype=_NP[t]))
                for x, t in zip(inputs, types)]
        hosts = [np.zeros((n, 3) if t.endswith("3") else n, dtype=_NP[t]) for t in self.rets[i]]
        outs = [cl.Buffer(ctx, mf.WRITE_ONLY, h.nbytes) for h in hosts]
        getattr(program, f"probe{i}")(queue, (n,), None, *bufs, *outs)
        for h, o in zip(hosts, outs):
            cl.enqueue_copy(queue, h, o)
        queue.finish()
        return hosts
