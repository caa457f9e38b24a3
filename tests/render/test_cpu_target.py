"""numba's CPU features as spacedg sets them: 512-bit vectors on the AVX-512 x86-64 hosts that keep
their clock, the user's setting first, numba's default once its target is set up; and the per-function
gather tuning of table-reading kernels on Zen 3 hosts."""

from __future__ import annotations

import os
import platform
import subprocess
import sys

import pytest
from llvmlite import binding
from numba.core import codegen, config

from spacedg.render import cpu_target

_PRINT = "import numba, spacedg.render; from spacedg.render import cpu_target; print(repr(numba.config.CPU_FEATURES), cpu_target.full_width_vectors())"


def _run(code: str, **env: str) -> subprocess.CompletedProcess:
    clean = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CPU_FEATURES", "NUMBA_CPU_NAME", cpu_target.VECTORS_ENV)}
    return subprocess.run([sys.executable, "-c", code], env={**clean, **env}, capture_output=True, text=True, timeout=120)


def _printed(code: str, **env: str) -> str:
    done = _run(code, **env)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_importing_spacedg_asks_numba_for_full_width_vectors_where_it_pays() -> None:
    host = codegen.get_host_cpu_features()
    avx512 = platform.machine().lower() in ("x86_64", "amd64") and "+avx512f" in host.split(",")
    wide = avx512 and binding.get_host_cpu_name() in cpu_target.FULL_WIDTH_CPUS
    assert _printed(_PRINT) == (f"'{host},-prefer-256-bit' True" if wide else "None False")
    assert _printed(_PRINT, SPACEDG_NUMBA_VECTORS="default") == "None False"
    assert _printed(_PRINT, SPACEDG_NUMBA_VECTORS="512") == (f"'{host},-prefer-256-bit' True" if avx512 else "None False")
    bad = _run(_PRINT, SPACEDG_NUMBA_VECTORS="wide")
    assert bad.returncode != 0 and "SPACEDG_NUMBA_VECTORS='wide': use auto (the default), 512 or default" in bad.stderr


def test_the_users_numba_setting_and_kernels_decorated_first_are_left_alone() -> None:
    host = codegen.get_host_cpu_features()
    assert _printed(_PRINT, NUMBA_CPU_FEATURES=host) == f"'{host}' False"  # numba's default, asked for by the user
    assert _printed(_PRINT, NUMBA_CPU_NAME="generic") == "'' False"  # (numba's own features for a generic CPU)
    # a kernel decorated (not even compiled) before spacedg's import: numba's target is set up, its features fixed
    assert _printed("import numba; numba.njit(lambda x: x + 1); " + _PRINT.replace("import numba, ", "import ")) == "None False"
    # what the check reads: numba sets its CPU target up at the first decoration (any host)
    probe = ("import numba; from spacedg.render.cpu_target import _target_initialised as t; "
             "before = t(); numba.njit(lambda x: x); print(before, t())")
    assert _printed(probe, SPACEDG_NUMBA_VECTORS="default") == "False True"


@pytest.mark.parametrize(("machine", "cpu", "features", "choice", "applied"), [
    ("x86_64", "emeraldrapids", "+64bit,+avx2,+avx512f,+fma", "auto", True),
    ("x86_64", "skylake-avx512", "+64bit,+avx2,+avx512f,+fma", "auto", False),  # its clock drops on 512-bit work
    ("x86_64", "skylake-avx512", "+64bit,+avx2,+avx512f,+fma", "512", True),  # asked for
    ("x86_64", "emeraldrapids", "+64bit,+avx2,+avx512f,+fma", "default", False),
    ("x86_64", "emeraldrapids", "+64bit,+avx2,-avx512f,+fma", "512", False),  # no AVX-512: nothing to prefer
    ("aarch64", "neoverse-v2", "+neon,+avx512f", "512", False),  # not x86: the tuning does not exist
])
def test_the_decision(monkeypatch: pytest.MonkeyPatch, machine: str, cpu: str, features: str, choice: str, applied: bool) -> None:
    monkeypatch.setattr(config, "CPU_FEATURES", None)
    monkeypatch.setattr(config, "CPU_NAME", None)
    monkeypatch.setenv(cpu_target.VECTORS_ENV, choice)
    monkeypatch.setattr(cpu_target, "_target_initialised", lambda: False)
    monkeypatch.setattr(cpu_target.platform, "machine", lambda: machine)
    monkeypatch.setattr(codegen, "get_host_cpu_features", lambda: features)
    monkeypatch.setattr(binding, "get_host_cpu_name", lambda: cpu)
    assert cpu_target.prefer_full_width_vectors() is applied
    assert config.CPU_FEATURES == (f"{features},-prefer-256-bit" if applied else None)


@pytest.mark.parametrize(("triple", "cpu", "features", "pays"), [
    ("x86_64-unknown-linux-gnu", "znver3", "+64bit,+avx,+avx2,+fma", True),  # measured: LLVM prices its gathers as scalar loads
    ("x86_64-unknown-linux-gnu", "znver3", "+64bit,+avx,-avx2", False),  # no AVX2: no gather instruction
    ("x86_64-unknown-linux-gnu", "znver3", "+64bit,+avx2,+fast-gather", False),  # said already
    ("x86_64-unknown-linux-gnu", "znver3", "+64bit,+avx,+avx2,-fast-gather", False),  # the user's NUMBA_CPU_FEATURES says no
    ("x86_64-unknown-linux-gnu", "znver2", "+64bit,+avx,+avx2,+fma", False),  # not measured
    ("x86_64-unknown-linux-gnu", "emeraldrapids", "+64bit,+avx2,+avx512f", False),  # Intel: the tuning is its CPU's own
    ("aarch64-unknown-linux-gnu", "znver3", "+neon,+avx2", False),  # not x86: the flag does not exist
])
def test_which_targets_gather_table_reads(triple: str, cpu: str, features: str, pays: bool) -> None:
    assert cpu_target.gathers_pay(triple, cpu, features) is pays


_TABLE_LOOP = """
import numba, numpy as np
from spacedg.render import kernel_cache
from spacedg.render.cpu_target import gathers_pay, vectorise_table_lookups

TABLE = np.arange(256, dtype=np.float64) ** 0.5  # a module constant, as the sensor's tables (an argument may alias out: no vector loop)

@numba.njit
def tuned(values, out):
    vectorise_table_lookups()
    for i in range(values.shape[0]):
        out[i] = TABLE[values[i] & 255] * 2.0

@numba.njit
def untuned(values, out):
    for i in range(values.shape[0]):
        out[i] = TABLE[values[i] & 255] * 2.0

for kernel in (tuned, untuned):
    kernel.compile("(int32[::1], float64[::1])")
ir = "".join(tuned.inspect_llvm().values())
gathers = ["vgather" in "".join(kernel.inspect_asm().values()) for kernel in (tuned, untuned)]
codegen = numba.core.registry.cpu_target.target_context.codegen()
print(gathers_pay(*codegen.magic_tuple()), '"target-features"=' in ir, "+fast-gather" in ir, *gathers)
"""


@pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"), reason="the tuning exists on x86-64 only")
def test_a_kernel_that_asks_is_tuned_on_the_hosts_that_decide_so_and_only_there() -> None:
    # numba's own target on this host: the attribute exactly where the decision says
    decided, has_attribute, has_flag, _, _ = _printed(_TABLE_LOOP).split()
    assert decided == has_attribute == has_flag
    # a Zen 3 target (compiled, not run): the function alone carries numba's features plus the flag, and LLVM
    # vectorises its table reads with gathers there, not its untuned twin's
    zen3 = "+64bit,+avx,+avx2,+fma,+sse4.2"
    assert _printed(_TABLE_LOOP, NUMBA_CPU_NAME="znver3", NUMBA_CPU_FEATURES=zen3) == "True True True True False"
    # Skylake carries the tuning itself: nothing added, both gather
    assert _printed(_TABLE_LOOP, NUMBA_CPU_NAME="skylake", NUMBA_CPU_FEATURES=zen3) == "False False False True True"
    # the user's -fast-gather is kept: neither gathers on Zen 3
    assert _printed(_TABLE_LOOP, NUMBA_CPU_NAME="znver3", NUMBA_CPU_FEATURES=zen3 + ",-fast-gather") == "False False False False False"
