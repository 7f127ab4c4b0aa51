"""The CPU wake-up latency request a lockstep flight holds (simbridge/cpu_latency.py)."""

from __future__ import annotations

import os
import struct

import pytest

from simbridge.client import connect, constant, run_lockstep
from simbridge.cpu_latency import PM_QOS_DEVICE, CpuLatencyRequest
from simbridge.launch import finish, start_sim


def kernel_latency_us() -> int:
    """The CPU latency bound the kernel now applies (reading the device gives it)."""
    fd = os.open(PM_QOS_DEVICE, os.O_RDONLY)
    try:
        return struct.unpack("i", os.read(fd, 4))[0]
    finally:
        os.close(fd)


can_request = os.access(PM_QOS_DEVICE, os.W_OK)


@pytest.mark.skipif(not can_request, reason=f"{PM_QOS_DEVICE} is not writable here")
def test_the_kernel_applies_the_request_while_it_is_held():
    with CpuLatencyRequest(0) as request:
        assert request.held
        assert kernel_latency_us() == 0
        assert request.describe() == "CPU wake-up latency held at 0 us"
    assert not request.held


def test_a_device_it_cannot_open_leaves_things_as_they_were(tmp_path):
    missing = tmp_path / "no_such_device"
    with CpuLatencyRequest(0, device=str(missing)) as request:
        assert not request.held
    assert str(missing) in request.describe() and "no such file" in request.describe()


def test_a_bad_latency_is_refused_with_its_range():
    with pytest.raises(ValueError, match=r"latency_us: -1 outside \[0, 2000000000\]"):
        CpuLatencyRequest(-1)


@pytest.mark.parametrize("declined", [False, True])
def test_the_simulator_says_what_became_of_the_request(declined):
    """A lockstep run as fast as possible asks for it unless declined; the summary says."""
    extra = ["--no-low-latency-idle"] if declined else []
    proc, port = start_sim(speedup="max", extra=extra, lockstep_start=True)
    sock = connect("127.0.0.1", port)
    try:
        view = run_lockstep(sock, 25, constant(0.0))
        assert "HIL_SENSOR" in view.latest
    finally:
        sock.close()
    report = finish(proc)
    if declined:
        assert "CPU wake-up latency not requested (declined)" in report
    elif can_request:
        assert "CPU wake-up latency held at 0 us" in report
    else:
        assert f"CPU wake-up latency not requested ({PM_QOS_DEVICE}:" in report


def test_a_paced_simulator_does_not_ask():
    proc, port = start_sim(speedup="4", lockstep_start=True)
    sock = connect("127.0.0.1", port)
    try:
        run_lockstep(sock, 5, constant(0.0))
    finally:
        sock.close()
    assert "CPU wake-up latency not requested (a paced run)" in finish(proc)
