"""The lockstep peers busy-poll only while the machine has a core to spare."""

from pathlib import Path

from simbridge.spin import SPIN_S, SpinPolicy, runnable_threads


def test_the_runnable_count_is_read_from_loadavg() -> None:
    assert runnable_threads("0.52 0.58 0.59 3/467 12345\n") == 3


def test_it_spins_only_while_no_more_threads_are_runnable_than_cores(tmp_path: Path) -> None:
    loadavg = tmp_path / "loadavg"
    loadavg.write_text("1.00 1.00 1.00 2/300 999\n")
    assert SpinPolicy(cores=2, loadavg=str(loadavg)).spin_s() == SPIN_S
    loadavg.write_text("4.00 4.00 4.00 4/300 999\n")  # two CPU-bound processes beside us
    assert SpinPolicy(cores=2, loadavg=str(loadavg)).spin_s() == 0.0


def test_without_a_readable_count_it_sleeps(tmp_path: Path) -> None:
    assert SpinPolicy(cores=2, loadavg=str(tmp_path / "absent")).spin_s() == 0.0
