"""C export of a model's generated functions: the files are written atomically, compile with the
system's C compiler (skipped without one) and evaluate as the Python functions do."""

from __future__ import annotations

import os
import shutil
import subprocess

import numpy as np
import pytest

from codegen.c_export import export_model_c
from codegen.functions import generate
from phs.workflows.cli import main
from systems.curling_hasel import curling_hasel
from systems.examples import mass_spring_damper


def _compiler():
    cc = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if cc is None:
        pytest.skip("no C compiler")
    return cc


def _program(name, x, u, p, n_y, n_m) -> str:
    arr = lambda v: "{" + ", ".join(repr(float(a)) for a in v) + ("" if len(v) else "0") + "}"  # noqa: E731
    return f"""#include <stdio.h>
#include <stdlib.h>
#include "{name}_model.h"
static void run(int (*f)(const casadi_real**, casadi_real**, casadi_int*, casadi_real*, int),
                int (*work)(casadi_int*, casadi_int*, casadi_int*, casadi_int*),
                const casadi_real* x, const casadi_real* u, const casadi_real* p, casadi_real** out) {{
  casadi_int n_arg, n_res, n_iw, n_w;
  work(&n_arg, &n_res, &n_iw, &n_w);
  const casadi_real** arg = malloc(sizeof(casadi_real*) * (n_arg + 3));
  casadi_real** res = malloc(sizeof(casadi_real*) * (n_res + 2));
  casadi_int* iw = malloc(sizeof(casadi_int) * (n_iw + 1));
  casadi_real* w = malloc(sizeof(casadi_real) * (n_w + 1));
  arg[0] = x; arg[1] = u; arg[2] = p; res[0] = out[0]; res[1] = out[1];
  if (f(arg, res, iw, w, 0)) exit(1);
}}
int main(void) {{
  casadi_real x[] = {arr(x)}, u[] = {arr(u)}, p[] = {arr(p)};
  casadi_real xdot[{len(x)}], y[{max(n_y, 1)}], m[{max(n_m, 1)}], H[1];
  casadi_real* o1[] = {{xdot, 0}}; casadi_real* o2[] = {{y, m}}; casadi_real* o3[] = {{H, 0}};
  run({name}_rhs, {name}_rhs_work, x, u, p, o1);
  run({name}_output, {name}_output_work, x, u, p, o2);
  run({name}_hamiltonian, {name}_hamiltonian_work, x, u, p, o3);
  for (int i = 0; i < {len(x)}; i++) printf("%.17g\\n", xdot[i]);
  for (int i = 0; i < {n_y}; i++) printf("%.17g\\n", y[i]);
  for (int i = 0; i < {n_m}; i++) printf("%.17g\\n", m[i]);
  printf("%.17g\\n", H[0]);
  return 0;
}}
"""


@pytest.mark.parametrize("build, x", [
    (mass_spring_damper, [0.3, 0.02]),
    (lambda: curling_hasel(2), None),
], ids=["msd", "curling2"])
def test_exported_c_compiles_and_matches_python(build, x, tmp_path):
    cc = _compiler()
    system = build()
    f = generate(system)
    p = system.param_vector()
    if x is None:
        from codegen.idapbc.model import state_vector

        x = state_vector(system, {"seg1.l_p": 0.015, "seg2.l_p": 0.015, "seg1.theta": 0.2, "seg2.theta": 0.1,
                                  "seg1.Q2": 1e-8})
    x = np.asarray(x, dtype=float)
    u = np.full(len(system.inputs), 0.7 if system.name == "msd" else 800.0)
    c_file, h_file = export_model_c(system, tmp_path / "c")
    name = os.path.basename(c_file)[: -len("_model.c")]
    n_y, n_m = len(system.inputs), len(system.measured)
    main_c = tmp_path / "main.c"
    main_c.write_text(_program(name, x, u, p, n_y, n_m))
    exe = tmp_path / "model"
    proc = subprocess.run([cc, "-std=c99", "-O2", "-I", str(tmp_path / "c"), str(main_c), c_file, "-o", str(exe), "-lm"],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    got = np.array([float(v) for v in subprocess.run([str(exe)], capture_output=True, text=True,
                                                         check=True).stdout.split()])
    y, m = f.output(x, u, p)
    want = np.concatenate([np.asarray(f.rhs(x, u, p)).ravel(), np.asarray(y).ravel(), np.asarray(m).ravel(),
                           np.asarray(f.hamiltonian(x, u, p)).ravel()])
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-300)
    header = open(h_file).read()
    assert f"model hash {system.model_hash()}" in header and f"{system.state_names[0]} [" in header


def test_phs_export_writes_two_files_and_nothing_else(tmp_path, capsys):
    out = tmp_path / "c"
    assert main(["export", "systems.examples:mass_spring_damper", "--param", "k.K=5", "--c", str(out)]) == 0
    assert sorted(os.listdir(out)) == ["msd_model.c", "msd_model.h"]
    assert "k.K = 5 [N/m]" in (out / "msd_model.h").read_text()
    assert "msd_rhs, msd_output, msd_hamiltonian" in capsys.readouterr().out


@pytest.mark.parametrize("args, words", [
    (["--c", "{tmp}/missing/c"], ["does not exist"]),
    (["--c", "{tmp}/file"], ["not a directory"]),
    (["--c", "{tmp}/c", "--param", "nope=1"], ["'nope'"]),
])
def test_phs_export_errors_exit_2_and_write_nothing(tmp_path, capsys, args, words):
    (tmp_path / "file").write_text("x")
    before = sorted(os.listdir(tmp_path))
    argv = ["export", "systems.examples:mass_spring_damper"] + [a.format(tmp=tmp_path) for a in args]
    assert main(argv) == 2
    err = capsys.readouterr().err
    for w in words:
        assert w in err, err
    assert sorted(os.listdir(tmp_path)) == before
