"""The text of an export's files: ``NAME.h`` (sizes, sample time, the prototypes and every
entry in words), ``NAME.c`` (CasADi's generated C of the step, the gains as data,
``NAME_init`` and ``NAME_step``), ``NAME.json`` (the manifest) and ``NAME_main.c`` (a CSV
bench harness).
"""

from __future__ import annotations

import json
import re

import casadi as ca

from airbearing.design.export_step import ExportSpec


def _literal(v: float) -> str:
    """A C double literal that reads back as exactly ``v``."""
    s = repr(float(v))
    return s if ("e" in s or "." in s or "inf" in s or "nan" in s) else s + ".0"


def _generated(fn: ca.Function, name: str, real: str) -> str:
    """CasADi's C for ``fn``: its helpers and its one evaluation function ``casadi_f0``
    (prefixed ``NAME_impl_``, all static), without the CasADi API around it (memory,
    reference counts, sparsity queries), which ``NAME_step`` does not need."""
    f = ca.Function(f"{name}_impl", fn.sx_in(), fn.call(fn.sx_in()), fn.name_in(), fn.name_out())
    opts = {"with_header": False, "main": False, "with_mem": False, "with_export": False,
            "casadi_real": real, "casadi_int": "int", "verbose": False, "cpp": False}  # fmt: skip
    cg = ca.CodeGenerator(f"{name}_impl.c", opts)
    cg.add(f)
    text = cg.dump()
    api = re.search(rf"^(?:CASADI_SYMBOL_EXPORT )?(?:static )?int {name}_impl\(", text, re.M)
    if api is None:
        raise RuntimeError("unexpected CasADi code: no entry point")
    text = text[: api.start()]
    text = re.sub(r"/\* Configuration this file was compiled with \*/.*?_casadi_real_size\(void\)"
                  r"[^\n]*\n", "", text, flags=re.S)  # fmt: skip
    out = []
    for line in text.splitlines():
        m = re.match(r"static const casadi_int (casadi_s\d+)\[", line)
        if m and len(re.findall(rf"\b{m.group(1)}\b", text)) <= 2:  # the #define and itself
            continue
        out.append(line)
        if line.startswith("static int casadi_f0("):
            out.append("  (void)arg; (void)res; (void)iw; (void)w; (void)mem;")
    return "\n".join(out).rstrip() + "\n"


def _prototypes(name: str, ny: int, nr: int, nx: int, nu: int) -> tuple[str, str]:
    """The parameter lists of ``NAME_step`` and of ``NAME_init``."""
    U = name.upper()

    def param(const: str, var: str, n: int) -> str:
        # an array parameter of size 0 is not ISO C: a pointer then (pass NULL)
        return (
            f"{const}{name}_real {var}[{U}_N{var.upper()}]" if n else f"{const}{name}_real* {var}"
        )

    sig = ", ".join([param("const ", "y", ny), param("const ", "r", nr), param("", "x", nx),
                     param("", "u", nu)])  # fmt: skip
    return sig, param("", "x", nx)


def _listing(sigs) -> str:
    """The entries of ``y``, ``r``, ``x`` or ``u`` as lines of the header's comment."""
    return "\n".join(f" *   {i:2d} {s.name} [{s.unit}]: {s.description}"
                     for i, s in enumerate(sigs)) or " *   (none)"  # fmt: skip


def _header(spec: ExportSpec, name: str, real: str, version: str) -> str:
    """The text of ``NAME.h``."""
    U = name.upper()
    ny, nr, nx, nu = len(spec.y), len(spec.r), len(spec.x), len(spec.u)
    sig, xparam = _prototypes(name, ny, nr, nx, nu)
    loop, tb = spec.meta.get("loop", ""), spec.meta.get("testbed", "")
    return f"""/* {name}.h: the {loop} controller of testbed '{tb}',
 * exported by airbearing {version} from the CasADi Function its simulation runs.
 * C99, no heap, libm only. Call {name}_init once, then {name}_step every {name.upper()}_DT s.
 *
 * y (measurements, log columns):
{_listing(spec.y)}
 * r (references, log columns):
{_listing(spec.r)}
 * x (controller state):
{_listing(spec.x)}
 * u (commands, log columns):
{_listing(spec.u)}
 */
#ifndef {U}_H
#define {U}_H

#ifdef __cplusplus
extern "C" {{
#endif

typedef {real} {name}_real;

#define {U}_NY {ny}   /* measurements */
#define {U}_NR {nr}   /* references */
#define {U}_NX {nx}   /* controller states (integrators, filters, held values) */
#define {U}_NU {nu}   /* commands */
#define {U}_DT {_literal(spec.dt)}   /* sample time, s */

void {name}_init({xparam});
int {name}_step({sig});   /* 0 on success */

#ifdef __cplusplus
}}
#endif

#endif
"""


def _source(spec: ExportSpec, name: str, real: str, version: str) -> str:
    """The text of ``NAME.c``: CasADi's C of ``spec.function`` and the step around it."""
    fn = spec.function
    U = name.upper()
    ny, nr, nx, nu = len(spec.y), len(spec.r), len(spec.x), len(spec.u)
    ng = len(spec.gains)
    sig, xparam = _prototypes(name, ny, nr, nx, nu)
    sz_arg, sz_res = fn.sz_arg(), fn.sz_res()
    sz_iw, sz_w = max(fn.sz_iw(), 1), max(fn.sz_w(), 1)
    gains_c = ", ".join(_literal(v) for v in spec.gains.values()) or "0"
    x0_c = "\n".join(f"    x[{i}] = {_literal(v)};" for i, v in enumerate(spec.x0))
    # float: the type-generic maths of C99, so that sin, sqrt, ... are sinf, sqrtf, ...
    # (single-precision FPUs); the generated code calls them by their double names
    math = "#include <math.h>" if real == "double" else "#include <tgmath.h>"
    gain_doc = ", ".join(f"{k} = {v!r}" for k, v in spec.gains.items())
    return f"""/* {name}.c: see {name}.h. Generated by airbearing {version}; do not edit the
 * generated part. The gains are data, not code: {name}_gains below ({gain_doc}). */
{math}
#include "{name}.h"

#define casadi_real {name}_real
#define casadi_int int

/* ---- generated by CasADi {ca.__version__} from the simulation's controller Function ---- */
{_generated(fn, name, real)}
/* ---- end of the generated part ---- */

/* gains, in the order {list(spec.gains)} */
static const {name}_real {name}_gains[{max(ng, 1)}] = {{{gains_c}}};

void {name}_init({xparam})
{{
{x0_c if nx else "    (void)x;"}
}}

int {name}_step({sig})
{{
    const {name}_real* arg[{sz_arg}];
    {name}_real* res[{sz_res}];
    int iw[{sz_iw}];
    {name}_real w[{sz_w}];
    {name}_real x_next[{max(nx, 1)}];
    int i;
    arg[0] = y;
    arg[1] = r;
    arg[2] = x;
    arg[3] = {name}_gains;
    res[0] = u;
    res[1] = x_next;
    if (casadi_f0(arg, res, iw, w, 0)) return 1;
    for (i = 0; i < {U}_NU; ++i) if (!isfinite(u[i])) return 2;
    for (i = 0; i < {U}_NX; ++i) if (!isfinite(x_next[i])) return 2;
    for (i = 0; i < {U}_NX; ++i) x[i] = x_next[i];
    return 0;
}}
"""


def manifest(spec: ExportSpec, name: str, real: str, version: str) -> str:
    """The text of ``NAME.json``."""
    data = {
        "name": name,
        "dt": spec.dt,
        "real": real,
        "y": [s.to_json() for s in spec.y],
        "r": [s.to_json() for s in spec.r],
        "x": [s.to_json() for s in spec.x],
        "u": [s.to_json() for s in spec.u],
        "x0": spec.x0.tolist(),
        "testbed": spec.meta.get("testbed"),
        "gains": spec.gains,
        **{k: v for k, v in spec.meta.items() if k != "testbed"},
        "airbearing_version": version,
    }
    return json.dumps(data, indent=2) + "\n"


def _harness(name: str, real: str, ny: int, nr: int, nu: int) -> str:
    U = name.upper()
    fmt = "%.17g" if real == "double" else "%.9g"
    return f"""/* {name}_main.c: bench harness for {name}_step. Reads one row per sample on stdin,
 * {U}_NY measurements then {U}_NR references, comma separated (the order of {name}.json's
 * "y" then "r"); a first line that is not numbers (a header) is skipped. Writes the
 * {U}_NU commands of each row on stdout. Exit status 1 on a malformed row or a failed step.
 * Build: cc -std=c99 -O2 {name}.c {name}_main.c -lm -o {name}_bench */
#include <stdio.h>
#include <stdlib.h>
#include "{name}.h"

int main(void)
{{
    char line[8192];
    {name}_real y[{U}_NY + 1], r[{U}_NR + 1], x[{U}_NX + 1], u[{U}_NU + 1];
    long row = 0;
    int first = 1;
    {name}_init(x);
    while (fgets(line, sizeof line, stdin)) {{
        char* p = line;
        char* end;
        int i;
        int bad = 0;
        if (line[0] == '\\n' || line[0] == '\\0') continue;
        for (i = 0; i < {U}_NY + {U}_NR; ++i) {{
            double v = strtod(p, &end);
            if (end == p) {{ bad = 1; break; }}
            if (i < {U}_NY) y[i] = ({name}_real)v; else r[i - {U}_NY] = ({name}_real)v;
            p = end;
            if (i + 1 < {U}_NY + {U}_NR) {{
                if (*p != ',') {{ bad = 1; break; }}
                ++p;
            }}
        }}
        if (bad) {{
            if (first) {{ first = 0; continue; }}   /* the header */
            fprintf(stderr, "row %ld: expected %d numbers\\n", row, {U}_NY + {U}_NR);
            return 1;
        }}
        first = 0;
        if ({name}_step(y, r, x, u) != 0) {{
            fprintf(stderr, "row %ld: step failed\\n", row);
            return 1;
        }}
        for (i = 0; i < {U}_NU; ++i) printf(i ? ",{fmt}" : "{fmt}", (double)u[i]);
        printf("\\n");
        ++row;
    }}
    return 0;
}}
"""
