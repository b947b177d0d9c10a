"""Outputs do not depend on the CPU: a replay and a closed-loop scenario give byte-identical commands,
trajectories and results on this machine as it is and on this machine made to compute like an x86-64-v2 CPU
(the oldest the project supports).

Every library that picks code by CPU at run time is turned back to its baseline in a fresh interpreter:
numpy's SIMD dispatch (``NPY_DISABLE_CPU_FEATURES``: its AVX2 / AVX-512 arctan2, exp, power), numba's code
generation (``NUMBA_CPU_NAME=generic``), OpenBLAS's kernels (``OPENBLAS_CORETYPE``: dot, matmul, solve) and
glibc's libm (``GLIBC_TUNABLES`` without AVX2 and FMA: its FMA variants of sin, cos, atan2, exp, pow). Each of
these changed the matcher's trajectory on a real log until the stack used gndreplay.detmath; a knob that has
nothing to turn off on this CPU (no AVX-512, say) changes nothing, and the check still holds for the others.
"""

from __future__ import annotations

import ast
import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
CLI = [sys.executable, "-c", "from gndreplay.cli import main; main()"]
REPLAY_FILES = ("commands.csv", "trajectory_corrected.tum", "trajectory_odom.tum")
SIM_FILES = (*REPLAY_FILES, "result.json", "log.mcap")


def baseline_cpu_env() -> dict[str, str]:
    """The environment that makes numpy, numba, OpenBLAS and glibc compute as on an x86-64-v2 CPU."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    env = dict(os.environ, NUMBA_CPU_NAME="generic")
    found = [f for f in __cpu_dispatch__ if __cpu_features__.get(f)]
    if found:
        env["NPY_DISABLE_CPU_FEATURES"] = " ".join(found)
    if platform.machine() in ("x86_64", "AMD64"):
        env["OPENBLAS_CORETYPE"] = "Prescott"
        # glibc >= 2.33 names the features AVX2 and FMA, older ones AVX2_Usable and FMA_Usable
        env["GLIBC_TUNABLES"] = "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX2_Usable,-FMA_Usable"
    return env


def gndreplay(args: list[str], env: dict[str, str] | None = None) -> None:
    proc = subprocess.run([*CLI, *args], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]


def outputs(folder: Path, names: tuple[str, ...]) -> dict[str, bytes]:
    return {name: (folder / name).read_bytes() for name in names}


def assert_same(got: dict[str, dict[str, bytes]]) -> None:
    a, b = got["default"], got["baseline"]
    changed = [name for name in a if a[name] != b[name]]
    assert not changed, f"{', '.join(changed)}: not the same on a baseline CPU"


@pytest.fixture(scope="module")
def machines() -> dict[str, dict[str, str] | None]:
    """The two ways of computing: this CPU as it is (None: the inherited environment) and the baseline."""
    return {"default": None, "baseline": baseline_cpu_env()}


def test_replay_of_the_sample_is_the_same_on_a_baseline_cpu(
        tmp_path: Path, machines: dict[str, dict[str, str] | None]) -> None:
    got: dict[str, dict[str, bytes]] = {}
    for name, env in machines.items():
        out = tmp_path / name
        gndreplay(["run", str(SAMPLE), "--until", "40", "--no-figures", "-q", "--out", str(out)], env)
        got[name] = outputs(out, REPLAY_FILES)
    assert_same(got)


def test_replay_of_a_real_log_is_the_same_on_a_baseline_cpu(
        tmp_path: Path, datasets: Path, machines: dict[str, dict[str, str] | None]) -> None:
    """ACES: the log on which the matcher's short-relation maximum moved with the CPU (3.25 / 2.24 deg)."""
    got: dict[str, dict[str, bytes]] = {}
    for name, env in machines.items():
        out = tmp_path / name
        gndreplay(["run", str(datasets / "carmen" / "aces.clf.bz2"), "--until", "120", "--no-figures", "-q",
                   "--out", str(out)], env)
        got[name] = outputs(out, REPLAY_FILES)
    assert_same(got)


def test_scenario_is_the_same_on_a_baseline_cpu(tmp_path: Path,
                                                 machines: dict[str, dict[str, str] | None]) -> None:
    """A closed loop with odometry noise and a walking person: the simulator's ray caster, noise and the
    stack all feed back into each other."""
    got: dict[str, dict[str, bytes]] = {}
    for name, env in machines.items():
        out = tmp_path / name
        gndreplay(["simulate", "gnd_fig2_person_crossing", "--seed", "3", "--no-figures", "--out", str(out)],
                  env)
        got[name] = outputs(out, SIM_FILES)
    assert_same(got)


# What the stack may not call: the system's transcendental functions (glibc picks FMA variants by CPU),
# numpy's (SIMD variants by CPU) and BLAS (kernels by CPU). gndreplay.detmath has the same functions, the
# same bits everywhere. Figures are exempt: they describe nothing a run is compared on.
FORBIDDEN_MATH = {"sin", "cos", "tan", "asin", "acos", "atan", "atan2", "exp", "expm1", "exp2", "log",
                  "log1p", "log2", "log10", "pow", "sinh", "cosh", "tanh", "asinh", "acosh", "atanh", "cbrt",
                  "erf", "erfc", "gamma", "lgamma"}
FORBIDDEN_NP = {"sin", "cos", "tan", "arcsin", "arccos", "arctan", "arctan2", "exp", "expm1", "exp2", "log",
                "log1p", "log2", "log10", "power", "float_power", "sinh", "cosh", "tanh", "cbrt", "dot",
                "vdot", "matmul", "einsum", "inner", "outer", "tensordot"}
PACKAGE = Path(__file__).resolve().parents[1] / "gndreplay"
FIGURES = {f"report/{p.name}" for p in (PACKAGE / "report").glob("*.py") if p.name != "mcap_export.py"}
EXEMPT = {"detmath.py", "cli.py", "sim/figure.py", *FIGURES}


def _is_int(node: ast.expr) -> bool:
    return isinstance(node, ast.Constant) and type(node.value) is int


def _compiled(fn: ast.FunctionDef) -> bool:
    return any("jit" in ast.unparse(d) or "vectorize" in ast.unparse(d) for d in fn.decorator_list)


def cpu_dependent_calls(path: Path) -> list[str]:
    """Lines of ``path`` that call CPU-dispatched math: see FORBIDDEN_*; ``a @ b``; ``x ** y`` unless both
    are integer literals, or y is one inside a numba kernel (numba multiplies; Python calls pow)."""
    found: list[str] = []

    def visit(node: ast.AST, compiled: bool) -> None:
        if isinstance(node, ast.FunctionDef):
            compiled = compiled or _compiled(node)
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            mod, name = node.value.id, node.attr
            if (mod == "math" and name in FORBIDDEN_MATH) or (mod == "np" and name in FORBIDDEN_NP):
                found.append(f"{path.name}:{node.lineno}: {mod}.{name}")
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Attribute)
                and ast.unparse(node.value) == "np.linalg" and node.attr != "LinAlgError"):
            found.append(f"{path.name}:{node.lineno}: np.linalg.{node.attr}")
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.MatMult):
            found.append(f"{path.name}:{node.lineno}: @")
        if (isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow)
                and not (_is_int(node.right) and (compiled or _is_int(node.left)))):
            found.append(f"{path.name}:{node.lineno}: {ast.unparse(node)}")
        for child in ast.iter_child_nodes(node):
            visit(child, compiled)

    visit(ast.parse(path.read_text()), False)
    return found


def test_the_stack_calls_no_cpu_dispatched_math() -> None:
    files = [p for p in sorted(PACKAGE.rglob("*.py")) if p.relative_to(PACKAGE).as_posix() not in EXEMPT]
    assert len(files) > 40
    found = [line for p in files for line in cpu_dependent_calls(p)]
    assert not found, "use gndreplay.detmath instead:\n" + "\n".join(found)


def test_the_check_sees_each_kind_of_call(tmp_path: Path) -> None:
    src = tmp_path / "m.py"
    src.write_text("import math\nimport numpy as np\nfrom numba import njit\n"
                   "a = math.sin(1.0) + np.arctan2(1, 2) + np.linalg.norm(x) + (m @ v) + y ** 2 + 2 ** 63\n"
                   "@njit\ndef k(x):\n    return x ** 2 + x ** 0.5\n")
    assert [line.split(": ")[1] for line in cpu_dependent_calls(src)] == [
        "math.sin", "np.arctan2", "np.linalg.norm", "@", "y ** 2", "x ** 0.5"]
