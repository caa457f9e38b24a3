"""``spacedg.devices.resolve_device``: a device this machine has, or one ParameterError naming the
argument, what it got and what is accepted (CUDA faked where the check needs a GPU)."""

from __future__ import annotations

import pytest
import torch

from spacedg.devices import resolve_device
from spacedg.errors import ParameterError


def test_cpu_and_none() -> None:
    assert resolve_device(None) is None
    assert resolve_device("cpu") == torch.device("cpu")
    assert resolve_device(" CPU ") == torch.device("cpu")
    assert resolve_device(torch.device("cpu"), "--device") == torch.device("cpu")


@pytest.mark.parametrize(("value", "fragment"), [
    ("", "is not a device name"),
    ("cuda:", "is not a device name"),
    ("cuda:-1", "is not a device name"),
    ("cuda:x", "is not a device name"),
    ("9" * 5000, "characters) is not a device name"),
    ("tpu", "unknown device type 'tpu'"),
    ("cpu:3", "there is one CPU device"),
    (3, "must be a device name"),
])
def test_malformed_and_unknown(value: object, fragment: str) -> None:
    with pytest.raises(ParameterError, match=r"^--device .*" + fragment.replace("(", r"\(").replace(")", r"\)")):
        resolve_device(value, "--device")  # type: ignore[arg-type]


def test_cuda_on_a_torch_without_cuda(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(torch.version, "cuda", None)
    monkeypatch.setattr(torch.version, "hip", None, raising=False)
    with pytest.raises(ParameterError, match=r"device 'cuda': this torch .* was built without CUDA; .* or pass cpu"):
        resolve_device("cuda")


def test_cuda_index_must_exist(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(torch.version, "cuda", "12.8")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    assert resolve_device("cuda:0") == torch.device("cuda", 0)
    assert resolve_device("cuda") == torch.device("cuda")
    with pytest.raises(ParameterError, match=r"^device 'cuda:7': there is 1 visible CUDA device \(cuda:0\)$"):
        resolve_device("cuda:7")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(ParameterError, match="no CUDA device is visible"):
        resolve_device("cuda:0")


def test_the_message_can_leave_the_argument_to_argparse() -> None:
    with pytest.raises(ParameterError, match=r"^'tpu': unknown device type"):
        resolve_device("tpu", argument="")
