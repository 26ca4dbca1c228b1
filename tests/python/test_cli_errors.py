# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Every `tofmat` command's error boundary: bad input is one line and exit status 2, a failure of
the system one line and status 1, -v adds the traceback, progress bars show on a terminal only."""

from __future__ import annotations

import logging
import os
import pty
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import click
import numpy as np
import pytest
from click.testing import CliRunner

from tofmat._clikit import EXIT_STATUS_HELP, FiniteFloat, NumberList
from tofmat.cli import main

NUMERIC = (click.types.IntParamType, click.types.FloatParamType, NumberList)


def commands(group: click.Group = main, path: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...], click.Command]]:
    """Every command below `group` (sub-groups walked), with the words that name it."""
    for name, cmd in sorted(group.commands.items()):
        if isinstance(cmd, click.Group):
            yield from commands(cmd, (*path, name))
        else:
            yield (*path, name), cmd


def numeric_options(cmd: click.Command) -> list[click.Option]:
    return [p for p in cmd.params if isinstance(p, click.Option) and isinstance(p.type, NUMERIC)]


ALL = list(commands())


def one_line(output: str) -> str:
    lines = [ln for ln in output.splitlines() if ln.strip()]
    assert len(lines) == 1, output
    assert "Traceback" not in output
    return lines[0]


def test_the_walk_finds_every_command() -> None:
    names = {" ".join(p) for p, _ in ALL}
    assert {"classify", "sim evaluate", "sim calibrate", "table import", "bench-line", "sort", "panel"} <= names
    assert len(names) >= 20


@pytest.mark.parametrize("words,cmd", ALL, ids=[" ".join(p) for p, _ in ALL])
def test_every_numeric_option_has_a_range_and_refuses_bad_values_in_one_line(
    words: tuple[str, ...], cmd: click.Command
) -> None:
    for opt in numeric_options(cmd):
        t = opt.type
        # A range on every number: plain int/float options let -1, 0 or 1e300 through to the code.
        assert isinstance(t, (click.IntRange, click.FloatRange, NumberList)), f"{' '.join(words)} {opt.opts[0]}"
        if isinstance(t, click.FloatRange):
            assert isinstance(t, FiniteFloat), f"{opt.opts[0]}: FloatRange lets NaN through"
        if isinstance(t, click.IntRange):
            bad = ["x", "-99999999999"]
        else:  # NumberList and FiniteFloat; a duration may have no upper end
            bad = ["not-a-number", "nan", "-1e300"] + (["1e300"] if getattr(t, "max", 0) is not None else [])
        if isinstance(t, click.IntRange) and t.max is not None:
            bad.append(str(t.max + 1))
        for value in bad:
            r = CliRunner().invoke(main, [*words, opt.opts[0], value])
            msg = one_line(r.output)
            assert r.exit_code == 2, (words, opt.opts[0], value, r.output)
            assert opt.opts[0] in msg and msg.startswith("Error: "), msg


@pytest.mark.parametrize("words,cmd", ALL, ids=[" ".join(p) for p, _ in ALL])
def test_every_help_ends_with_the_exit_statuses(words: tuple[str, ...], cmd: click.Command) -> None:
    r = CliRunner().invoke(main, [*words, "--help"])
    assert r.exit_code == 0
    assert " ".join(r.output.split()).endswith(EXIT_STATUS_HELP), r.output


@pytest.fixture(scope="module")
def query(tmp_path_factory: pytest.TempPathFactory, real_table) -> Path:  # type: ignore[no-untyped-def]
    q = np.full((real_table.n_rows, real_table.n_bins), np.nan, np.float32)
    q[:, 40:50] = real_table.features[real_table.materials.index("cork"), :, 40:50]
    path = tmp_path_factory.mktemp("q") / "q.npy"
    np.save(path, q)
    return path


def test_the_cases_users_met(db_dir: Path, query: Path, tmp_path: Path) -> None:
    """The inputs that once ended in a traceback or were accepted: each is one line, status 2."""
    db = str(db_dir)
    cases = [
        (["sim", "evaluate", "--materials", "unobtainium"], "unobtainium"),
        (["sim", "evaluate", "--step", "0"], "--step"),
        (["sim", "bench", "--frames", "0"], "--frames"),
        (["sweeps", "--table", db, "--sweeps", "0"], "--sweeps"),
        (["classify", "--table", db, "--top", "-1", str(query)], "--top"),
        (["classify", "--table", db, "--materials", "cork,unobtainium", str(query)], "unobtainium"),
        (["classify", "--table", db, str(tmp_path / "missing.npy")], "missing.npy"),
        (["table", "info", str(tmp_path / "missing.tmx")], "missing.tmx"),
        (["sim", "table", "--materials", "cork,nope", "-o", str(tmp_path / "t.tmx")], "nope"),
        (["sim", "table", "--range", "1200,600", "-o", str(tmp_path / "t.tmx")], "START < END"),
        (["sim", "table", "--range", "600", "-o", str(tmp_path / "t.tmx")], "START < END"),
        (["sim", "table", "--range", "100,900", "-o", str(tmp_path / "t.tmx")], "--range"),
        (["bench", "--table", db, "--backends", "float,nope"], "nope"),
        (["bench", "--table", db, "--windows", "0"], "--windows"),
        (["bench-daemon", "--clients", "0"], "--clients"),
        (["sim", "calibrate", "--db", str(tmp_path)], "no .npy files"),
    ]
    for args, says in cases:
        r = CliRunner().invoke(main, args)
        assert r.exit_code == 2, (args, r.exit_code, r.output)
        assert says in one_line(r.output), (args, r.output)
    # A file that is there but holds no table is bad input too.
    junk = tmp_path / "junk.tmx"
    junk.write_bytes(b"not a table at all")
    r = CliRunner().invoke(main, ["table", "info", str(junk)])
    assert r.exit_code == 2 and "junk.tmx" in one_line(r.output)


def test_a_failure_of_the_system_is_status_1_and_verbose_shows_the_traceback(tmp_path: Path) -> None:
    sock = str(tmp_path / "nobody.sock")
    r = CliRunner().invoke(main, ["status", "--address", sock])
    assert r.exit_code == 1 and "cannot connect" in one_line(r.output)
    # -v: the same error, with the traceback of an unexpected exception above it.
    r = CliRunner().invoke(main, ["-v", "sim", "calibrate", "--db", str(tmp_path)])
    assert r.exit_code == 2
    assert "Traceback" in r.output and r.output.rstrip().splitlines()[-1].startswith("Error: ")


def _run_on_a_terminal(args: list[str]) -> tuple[int, str]:
    """The command with stderr on a pseudo-terminal (where progress bars are drawn)."""
    leader, follower = pty.openpty()
    p = subprocess.Popen([sys.executable, "-m", "tofmat", *args], stdout=subprocess.DEVNULL, stderr=follower)
    os.close(follower)
    chunks = []
    while True:
        try:
            data = os.read(leader, 4096)
        except OSError:  # EIO: the child closed the terminal
            break
        if not data:
            break
        chunks.append(data)
    os.close(leader)
    return p.wait(timeout=300), b"".join(chunks).decode(errors="replace")


def test_long_jobs_show_a_progress_bar_on_a_terminal_and_none_with_q(tmp_path: Path) -> None:
    args = ["sim", "table", "--materials", "cork,paper,wood", "--bins", "20", "--calibration-sessions", "0"]
    args += ["-o", str(tmp_path / "t.tmx")]
    rc, err = _run_on_a_terminal(args)
    assert rc == 0, err
    assert "recording materials" in err and "3/3" in err, err  # what it does, and how far it is
    rc, err = _run_on_a_terminal(["-q", *args])
    assert rc == 0 and "recording materials" not in err, err
    # Not on a terminal (a log, a pipe): results only.
    p = subprocess.run([sys.executable, "-m", "tofmat", *args], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0 and p.stderr == "", p.stderr


def test_the_cores_logs_reach_python_logging_never_stdout(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, capfd: pytest.CaptureFixture[str]
) -> None:
    """With no camera (as here), the driver's retry warnings go to logging.getLogger("tofmat.core"),
    and the failure names their reason instead of 'stopped: stopped'."""
    from tofmat import _tofmat
    from tofmat.client import sim_data_dir

    caplog.set_level(logging.WARNING, logger="tofmat.core")
    with pytest.raises(RuntimeError, match=r"recorded 0 of 1 frames before the timeout: .*no Kinect v2 found"):
        _tofmat.record("kinect", str(tmp_path / "r.rec"), 1, str(sim_data_dir()), 1.0)
    core = [r for r in caplog.records if r.name == "tofmat.core"]
    assert core and all(r.levelno == logging.WARNING for r in core)
    assert "no Kinect v2 found" in core[0].getMessage()
    out, _ = capfd.readouterr()
    assert out == ""  # the C++ logger wrote to stdout
    # The command: one line, status 1, nothing on stdout.
    p = subprocess.run([sys.executable, "-m", "tofmat", "record", "--source", "kinect", "-o", str(tmp_path / "r.rec"),
                        "--frames", "1", "--timeout", "1"], capture_output=True, text=True, timeout=60)  # fmt: skip
    assert p.returncode == 1 and p.stdout == ""
    assert "no Kinect v2 found" in one_line(p.stderr)
