# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""mk/fuzz.sh, the runner behind `make fuzz`: a failing target fails the run once all have run,
and its report and its input are at the end of the output, so a CI log's tail says which target
failed and on what input. Stand-in "fuzzers" (shell scripts that take libFuzzer's flags) play
the targets."""

from __future__ import annotations

import re
import stat
import subprocess
from pathlib import Path

from conftest import REPO

RUNNER = REPO / "mk" / "fuzz.sh"

# Says the seed it was given, as libFuzzer does.
PASSING = """#!/usr/bin/env bash
for a in "$@"; do case $a in -seed=*) echo "INFO: Seed: ${a#-seed=}";; esac; done
echo "#2 INITED"
echo "stat::number_of_executed_units: 1234"
"""

# Writes its input where -artifact_prefix says, as libFuzzer does on a crash, and exits 77.
FAILING = """#!/usr/bin/env bash
for a in "$@"; do case $a in -artifact_prefix=*) prefix=${a#-artifact_prefix=};; esac; done
echo "#2 INITED"
echo "==42==ERROR: AddressSanitizer: heap-buffer-overflow on address 0x1"
echo "SUMMARY: AddressSanitizer: heap-buffer-overflow"
printf 'in\\x00put\\xff' > "${prefix}crash-0123"
echo "Test unit written to ${prefix}crash-0123"
exit 77
"""


def _targets(tmp_path: Path, scripts: dict[str, str]) -> Path:
    build = tmp_path / "build"
    (build / "tests" / "fuzz").mkdir(parents=True)
    for name, text in scripts.items():
        path = build / "tests" / "fuzz" / name
        path.write_text(text)
        path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return build


def _run(build: Path, seed: int = 0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["bash", str(RUNNER), str(build), "1", "2", str(seed)], cwd=REPO, capture_output=True, text=True, timeout=60
    )


def test_every_target_passing_passes(tmp_path: Path) -> None:
    build = _targets(tmp_path, {"fuzz_a": PASSING, "fuzz_b": PASSING})
    result = _run(build, seed=5)
    assert result.returncode == 0, result.stdout + result.stderr
    # The seed given reaches every target, so the run can be repeated.
    assert "fuzz: fuzz_a for 1 s, seed 5: number_of_executed_units: 1234 (exit 0)" in result.stdout
    assert "fuzz: fuzz_b for 1 s, seed 5: number_of_executed_units: 1234 (exit 0)" in result.stdout
    assert "FAILED" not in result.stdout


def test_a_failure_is_reported_last_with_its_input(tmp_path: Path) -> None:
    # The failing target sorts first, so its own line comes early: its report must come at the end.
    build = _targets(tmp_path, {"fuzz_a": FAILING, "fuzz_b": PASSING, "fuzz_c": PASSING})
    result = _run(build)
    assert result.returncode == 1
    out = result.stdout
    tail = out[out.index("fuzz: FAILED") :]
    assert "fuzz_c for 1 s" not in tail  # every target's line came before the report
    assert tail.startswith("fuzz: FAILED fuzz_a (exit 77, seed ")
    assert "ERROR: AddressSanitizer: heap-buffer-overflow" in tail
    assert "fuzz: fuzz_a input fuzz_a-crash-0123, 7 bytes" in tail
    # The hint's own command replays it: the lines between the two markers are what base64 -d reads.
    encoded = re.search(r"its base64.*\n((?:.*\n)*?)fuzz: end\n", tail)
    assert encoded is not None, tail
    decoded = subprocess.run(["base64", "-d"], input=encoded.group(1).encode(), capture_output=True, check=True)
    assert decoded.stdout == b"in\x00put\xff"
    # The whole log is kept beside the build.
    assert "Test unit written" in (build / "logs" / "fuzz_a.log").read_text()


def test_a_target_that_dies_without_a_report_shows_its_last_lines(tmp_path: Path) -> None:
    silent = '#!/usr/bin/env bash\necho "ParseDictionaryFile: error in line 3"\nexit 1\n'
    build = _targets(tmp_path, {"fuzz_a": silent})
    result = _run(build)
    assert result.returncode == 1
    tail = result.stdout[result.stdout.index("fuzz: FAILED") :]
    assert "ParseDictionaryFile: error in line 3" in tail


def test_every_failure_is_reported(tmp_path: Path) -> None:
    build = _targets(tmp_path, {"fuzz_a": FAILING, "fuzz_b": PASSING, "fuzz_c": FAILING})
    result = _run(build)
    assert result.returncode == 1
    reports = re.findall(r"^fuzz: FAILED (\S+) \(exit ([^,]+)", result.stdout, re.M)
    assert reports == [("fuzz_a", "77"), ("fuzz_c", "77")]


def test_a_target_without_a_result_is_a_failure(tmp_path: Path) -> None:
    # The runner's shell dies (as under the OOM killer): no exit code is written, and xargs stops.
    killer = "#!/usr/bin/env bash\nkill -9 $PPID\n"
    build = _targets(tmp_path, {"fuzz_a": killer})
    result = _run(build)
    assert result.returncode == 1
    assert "fuzz: FAILED fuzz_a (exit none (its runner did not finish)" in result.stdout


def test_a_build_without_targets_is_an_error(tmp_path: Path) -> None:
    build = _targets(tmp_path, {})
    result = _run(build)
    assert result.returncode == 1
    assert "no fuzz targets" in result.stderr
