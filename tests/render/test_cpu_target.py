"""numba's CPU features as spacedg sets them: 512-bit vectors on AVX-512 x86-64 hosts, the user's setting first."""

from __future__ import annotations

import os
import platform
import subprocess
import sys

import pytest
from numba.core import codegen, config

from spacedg.render import cpu_target

_PRINT = "import numba, spacedg.render; from spacedg.render import cpu_target; print(repr(numba.config.CPU_FEATURES), cpu_target.full_width_vectors())"


def _run(code: str, **env: str) -> str:
    clean = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CPU_FEATURES", "NUMBA_CPU_NAME")}
    done = subprocess.run([sys.executable, "-c", code], env={**clean, **env}, capture_output=True, text=True, timeout=120, check=True)
    return done.stdout.strip()


def test_importing_spacedg_asks_numba_for_full_width_vectors_on_avx512_hosts() -> None:
    host = codegen.get_host_cpu_features()
    wide = platform.machine().lower() in ("x86_64", "amd64") and "+avx512f" in host.split(",")
    assert _run(_PRINT) == (f"'{host},-prefer-256-bit' True" if wide else "None False")


def test_the_users_numba_setting_and_code_compiled_first_are_left_alone() -> None:
    host = codegen.get_host_cpu_features()
    assert _run(_PRINT, NUMBA_CPU_FEATURES=host) == f"'{host}' False"  # numba's default, asked for by the user
    assert _run(_PRINT, NUMBA_CPU_NAME="generic") == "'' False"  # (numba's own features for a generic CPU)
    # numba compiled before spacedg was imported: its CPU target is set up, the features are fixed
    compiled_first = "import numba; numba.njit(lambda x: x + 1)(1); " + _PRINT.replace("import numba, ", "import ")
    assert _run(compiled_first) == "None False"


@pytest.mark.parametrize(("machine", "features", "applied"), [
    ("x86_64", "+64bit,+avx2,+avx512f,+fma", True),
    ("x86_64", "+64bit,+avx2,-avx512f,+fma", False),  # no AVX-512: nothing to prefer
    ("aarch64", "+neon,+avx512f", False),  # not x86: the tuning does not exist
])
def test_the_decision(monkeypatch: pytest.MonkeyPatch, machine: str, features: str, applied: bool) -> None:
    monkeypatch.setattr(config, "CPU_FEATURES", None)
    monkeypatch.setattr(config, "CPU_NAME", None)
    monkeypatch.setattr(cpu_target, "_target_initialised", lambda: False)
    monkeypatch.setattr(cpu_target.platform, "machine", lambda: machine)
    monkeypatch.setattr(codegen, "get_host_cpu_features", lambda: features)
    assert cpu_target.prefer_full_width_vectors() is applied
    assert config.CPU_FEATURES == (f"{features},-prefer-256-bit" if applied else None)
    assert cpu_target.full_width_vectors() is applied
