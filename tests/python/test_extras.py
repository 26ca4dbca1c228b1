# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The SDK's dependency split: the core (numpy, click) works without the optional extras.

`pip install ./sdk` installs numpy and click only; scipy and matplotlib come with the `sim`, `plot`
and `all` extras, smbus2 and Pillow with `hw` and `all` (sdk/pyproject.toml). Here a subprocess
blocks all four (a meta path finder installed before tofmat is imported, which also logs every
attempt to import them) and runs what the board runs: `import tofmat`, the classifier on the real
database, the client against a live tofmatd, the `tofmat` command's table, classify, watch, status,
record and devices, and the tofmat.hw drivers on their simulated chips. Nothing there may even try
to import an extra. What does need one exits 1 with one line (or raises MissingExtraError) naming
the extra to install.
"""

from __future__ import annotations

import ast
import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
import tomllib
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import tofmat
from tofmat._extras import MissingExtraError, require

REPO = Path(__file__).resolve().parents[2]
SDK = REPO / "sdk"
BLOCKED = ("scipy", "matplotlib", "smbus2", "PIL", "sklearn", "onnx", "onnxruntime")  # import names
CORE = ["numpy", "click"]  # the decided core dependencies (by name)
EXTRAS = {"sim": {"scipy", "matplotlib"}, "plot": {"matplotlib"}, "hw": {"smbus2", "pillow"},
          "learn": {"scikit-learn", "onnx", "onnxruntime"},
          "all": {"scipy", "matplotlib", "smbus2", "pillow", "scikit-learn", "onnx", "onnxruntime"}}  # fmt: skip
DISTRIBUTION = {
    "PIL": "pillow",
    "sklearn": "scikit-learn",
}  # import name -> the name pip installs it by, where they differ

# Runs first in every subprocess: importing a blocked package (or a submodule) fails as if it were
# not installed, and each attempt is appended to the file named by $TOFMAT_TEST_IMPORT_LOG.
BLOCKER = textwrap.dedent(
    f"""
    import importlib.abc, os, sys

    BLOCKED = {BLOCKED!r}
    assert not [m for m in sys.modules if m.split(".")[0] in BLOCKED], "imported before the blocker"

    class _Blocker(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] not in BLOCKED:
                return None
            with open(os.environ["TOFMAT_TEST_IMPORT_LOG"], "a") as fh:
                fh.write(name + "\\n")
            raise ModuleNotFoundError(f"No module named {{name!r}} (blocked by test_extras)", name=name)

    sys.meta_path.insert(0, _Blocker())
    """
)
# `python -m tofmat ARGS...` behind the blocker.
RUN_CLI = "import runpy; runpy.run_module('tofmat', run_name='__main__', alter_sys=True)"


class Blocked:
    """Runs Python code or the `tofmat` command in a subprocess without the extras' packages."""

    def __init__(self, workdir: Path) -> None:
        self.workdir = workdir
        self.log = workdir / "blocked_imports.txt"

    def attempts(self) -> list[str]:
        """Names of the blocked modules that something tried to import since the last call."""
        names = self.log.read_text().split() if self.log.exists() else []
        self.log.unlink(missing_ok=True)
        return names

    def python(self, code: str, *args: str | Path, timeout: float = 120.0) -> subprocess.CompletedProcess[str]:
        env = dict(os.environ, TOFMAT_TEST_IMPORT_LOG=str(self.log))  # (PYTHONPATH and the rest inherited)
        return subprocess.run([sys.executable, "-c", BLOCKER + textwrap.dedent(code), *map(str, args)],
                              capture_output=True, text=True, timeout=timeout, cwd=self.workdir, env=env)  # fmt: skip

    def cli(self, *args: str | Path, timeout: float = 120.0) -> subprocess.CompletedProcess[str]:
        return self.python(RUN_CLI, *args, timeout=timeout)


def ok(p: subprocess.CompletedProcess[str]) -> subprocess.CompletedProcess[str]:
    assert p.returncode == 0, f"exit {p.returncode}:\n{p.stdout}\n{p.stderr}"
    assert "Traceback" not in p.stderr
    return p


def one_line_error(p: subprocess.CompletedProcess[str]) -> str:
    """Exit status 1, exactly one line on stderr, no traceback; that line."""
    assert p.returncode == 1, f"exit {p.returncode}:\n{p.stdout}\n{p.stderr}"
    assert "Traceback" not in p.stderr and "Traceback" not in p.stdout
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, p.stderr
    return lines[0]


@pytest.fixture(scope="module")
def blocked(tmp_path_factory: pytest.TempPathFactory) -> Blocked:
    return Blocked(tmp_path_factory.mktemp("extras"))


@pytest.fixture(autouse=True)
def _fresh_import_log(blocked: Blocked) -> None:
    blocked.attempts()  # what an earlier (failed) test left is not this test's


@pytest.fixture(scope="module")
def core_tmx(blocked: Blocked, db_dir: Path) -> Path:
    """The real database imported into a .tmx file by `tofmat table import`, without the extras."""
    out = blocked.workdir / "db.tmx"
    blocked.attempts()  # (set up before the autouse fixture clears the log)
    p = ok(blocked.cli("table", "import", db_dir, "-o", out))
    assert out.is_file() and "29 materials" in p.stdout
    assert blocked.attempts() == []
    return out


# --- the core without the extras -------------------------------------------------------------


def test_import_tofmat_and_classify_without_the_extras(blocked: Blocked, db_dir: Path) -> None:
    p = blocked.python(
        """
        import sys
        import numpy as np
        import tofmat

        assert issubclass(tofmat.MissingExtraError, ImportError) and "MissingExtraError" in tofmat.__all__
        table = tofmat.ExemplarTable.from_npy_dir(sys.argv[1])
        query = np.full((table.n_rows, table.n_bins), np.nan, np.float32)
        query[:, 40:50] = table.features[table.index_of("cork"), :, 40:50]
        for backend in ("float", "fixed"):
            r = tofmat.Classifier(table, backend=backend, method="eq12").classify(query)
            print(backend, r.material, r.valid)
        try:
            tofmat.Client(sys.argv[2], timeout=1.0, reconnect=False)
        except tofmat.DaemonUnavailableError as e:
            print("client:", type(e).__name__)
        """,
        db_dir,
        blocked.workdir / "nobody-listens.sock",
    )
    ok(p)
    assert p.stdout.splitlines() == ["float cork 20", "fixed cork 20", "client: DaemonUnavailableError"]
    assert blocked.attempts() == []


def test_every_module_imports_without_the_extras(blocked: Blocked) -> None:
    """No module of the package imports an extra at import time (only inside what needs it)."""
    p = ok(blocked.python(
        """
        import importlib, pkgutil
        import tofmat

        names = [m.name for m in pkgutil.walk_packages(tofmat.__path__, "tofmat.") if m.name != "tofmat.__main__"]
        for name in names:
            importlib.import_module(name)
        print(" ".join(names))
        """
    ))  # fmt: skip
    imported = p.stdout.split()
    for name in ("tofmat.cli", "tofmat.client", "tofmat.tools.plot", "tofmat.sim.plots", "tofmat.sim.calibrate",
                 "tofmat.sim.model_np", "tofmat.sim.evaluate", "tofmat.sim.cli", "tofmat.hw", "tofmat.hw.bus",
                 "tofmat.hw.pca9685", "tofmat.hw.ssd1306", "tofmat.hw.fake_pca9685",
                 "tofmat.hw.fake_ssd1306"):  # fmt: skip
        assert name in imported
    assert blocked.attempts() == []


def test_table_and_classify_commands_without_the_extras(blocked: Blocked, core_tmx: Path, db_dir: Path,
                                                        real_table: tofmat.ExemplarTable) -> None:  # fmt: skip
    p = ok(blocked.cli("table", "info", core_tmx))
    assert "29 materials x 2 rows x 200 bins" in p.stdout
    p = ok(blocked.cli("table", "info", db_dir, "--json"))
    assert len(json.loads(p.stdout)["materials"]) == 29
    query = np.full((real_table.n_rows, real_table.n_bins), np.nan, np.float32)
    query[:, 100:140] = real_table.features[real_table.index_of("paper"), :, 100:140]
    q = blocked.workdir / "paper.npy"
    np.save(q, query)
    p = ok(blocked.cli("classify", "--table", core_tmx, q, "--json"))
    assert json.loads(p.stdout)["material"] == "paper"
    p = ok(blocked.cli("classify", "--table", db_dir, q))
    assert p.stdout.startswith("paper ")
    assert blocked.attempts() == []


def test_record_and_devices_without_the_extras(blocked: Blocked) -> None:
    rec = blocked.workdir / "cork.tmrec"
    p = ok(blocked.cli("record", "--source", "sim:static,material=cork,depth=800,realtime=0", "-o", rec,
                       "--frames", "1", "--timeout", "60"))  # fmt: skip
    assert rec.is_file() and "1 frames" in p.stdout
    p = blocked.cli("devices")  # no camera here: one line saying so; with one, its description
    assert p.returncode in (0, 1) and "Traceback" not in p.stderr
    if p.returncode == 1:
        assert "Kinect v2" in one_line_error(p)
    assert blocked.attempts() == []


@pytest.fixture
def live_daemon(blocked: Blocked, core_tmx: Path, tmp_path: Path) -> Iterator[Path]:
    """tofmatd on the simulated camera (a static cork target), its Unix socket."""
    from tofmat.client import daemon_binary, sim_data_dir

    sock, log = tmp_path / "d.sock", tmp_path / "d.log"
    cmd = [str(daemon_binary()), "--source", "sim:static,material=cork,depth=850,realtime=0", "--table", str(core_tmx),
           "--socket", str(sock), "--sim-data", str(sim_data_dir())]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=log.open("wb"), stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 30.0
        while True:
            assert proc.poll() is None, f"tofmatd exited: {log.read_text()}"
            try:
                tofmat.Client(sock, reconnect=False).close()
                break
            except tofmat.DaemonUnavailableError:
                assert time.monotonic() < deadline, "tofmatd did not listen within 30 s"
                time.sleep(0.05)
        yield sock
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            proc.wait(20)


def test_client_watch_and_status_without_the_extras(blocked: Blocked, live_daemon: Path) -> None:
    p = ok(blocked.python(
        """
        import sys
        import tofmat

        with tofmat.Client(sys.argv[1]) as c:
            label = next(c.labels(timeout=30.0))
            print(type(label).__name__, c.status()["profile"])
        """,
        live_daemon,
    ))  # fmt: skip
    assert p.stdout.split() == ["Label", "handheld"]
    p = ok(blocked.cli("status", "--address", live_daemon))
    assert json.loads(p.stdout)["profile"] == "handheld"
    p = ok(blocked.cli("watch", "--address", live_daemon, "--count", "3"))
    assert sum(line.startswith("frame ") for line in p.stdout.splitlines()) == 3
    assert blocked.attempts() == []


def test_client_commands_report_no_daemon_in_one_line(blocked: Blocked) -> None:
    for cmd in ("status", "watch"):
        p = blocked.cli(cmd, "--address", blocked.workdir / "nobody.sock")
        assert "cannot connect to tofmatd" in one_line_error(p)
    assert blocked.attempts() == []


# --- what needs an extra says which ----------------------------------------------------------


def test_plot_table_needs_the_plot_extra(blocked: Blocked, core_tmx: Path) -> None:
    out = blocked.workdir / "curves.png"
    msg = one_line_error(blocked.cli("plot", "table", core_tmx, "-o", out))
    assert msg == "Error: tofmat plot table needs matplotlib: pip install 'tofmat[plot]'"
    assert not out.exists()
    assert blocked.attempts() == ["matplotlib"]
    assert "Plot every material" in ok(blocked.cli("plot", "table", "--help")).stdout


def test_sim_calibrate_and_evaluate_need_the_sim_extra(blocked: Blocked, db_dir: Path) -> None:
    p = ok(blocked.cli("sim", "calibrate", "--help"))  # help never needs an extra
    assert "--db" in p.stdout
    msg = one_line_error(blocked.cli("sim", "calibrate", "--db", db_dir, "--out", blocked.workdir / "calib"))
    assert msg == "Error: tofmat sim calibrate needs scipy: pip install 'tofmat[sim]'"
    assert not (blocked.workdir / "calib").exists()
    assert blocked.attempts() == ["scipy"]
    msg = one_line_error(blocked.cli("sim", "evaluate", "--materials", "cork", "--out", blocked.workdir / "eval"))
    assert msg == "Error: tofmat sim evaluate needs matplotlib: pip install 'tofmat[sim]'"
    assert blocked.attempts() == ["matplotlib"]


def test_train_and_learned_models_need_the_learn_extra(blocked: Blocked, core_tmx: Path) -> None:
    assert "--hidden" in ok(blocked.cli("train", "--help")).stdout
    out = blocked.workdir / "model.onnx"
    msg = one_line_error(blocked.cli("train", "--table", core_tmx, "-o", out))
    assert msg == "Error: tofmat train needs sklearn: pip install 'tofmat[learn]'"
    assert not out.exists()
    assert blocked.attempts() == ["sklearn"]
    model = REPO / "tests" / "cpp" / "data" / "onnx" / "tiny_mlp.onnx"
    ok(blocked.python(
        """
        import sys
        import tofmat
        from tofmat.learn import LearnedClassifier

        try:
            LearnedClassifier(sys.argv[1])
            raise SystemExit("LearnedClassifier did not raise")
        except tofmat.MissingExtraError as e:
            assert (e.module, e.extra) == ("onnxruntime", "learn"), (e.module, e.extra)
        """,
        model,
    ))  # fmt: skip
    assert blocked.attempts() == ["onnxruntime"]


def test_library_functions_raise_missing_extra_error(blocked: Blocked, core_tmx: Path) -> None:
    ok(blocked.python(
        """
        import sys
        import numpy as np
        import tofmat
        from tofmat.sim import model_np
        from tofmat.tools.plot import plot_table

        try:
            plot_table(tofmat.ExemplarTable.load(sys.argv[1]), "never.png")
            raise SystemExit("plot_table did not raise")
        except tofmat.MissingExtraError as e:
            assert isinstance(e, ImportError) and (e.module, e.extra, e.name) == ("matplotlib", "plot", "matplotlib")
            assert str(e).endswith("needs matplotlib: pip install 'tofmat[plot]'"), str(e)
        d = np.full((3, 4), 900.0)
        assert model_np.expected_wrapped(d, 0.0) is d  # noise-free: no scipy needed
        try:
            model_np.expected_wrapped(d, 0.5)
            raise SystemExit("expected_wrapped did not raise")
        except tofmat.MissingExtraError as e:
            assert (e.module, e.extra) == ("scipy", "sim") and "pip install 'tofmat[sim]'" in str(e), str(e)
        """,
        core_tmx,
    ))  # fmt: skip
    assert blocked.attempts() == ["matplotlib", "scipy"]


def test_hw_needs_its_extra_only_for_a_real_bus_and_pictures(blocked: Blocked) -> None:
    """The drivers run on the simulated chips with numpy alone; a real bus needs smbus2, text and
    PNGs need Pillow, and each says to install tofmat[hw]."""
    ok(blocked.python(
        """
        import numpy as np
        import tofmat
        from tofmat.hw import PCA9685, SSD1306, FakePCA9685Bus, FakeSSD1306Bus, Servo, open_bus, render_text

        pca_bus = FakePCA9685Bus()
        pca = PCA9685(pca_bus)
        pca.set_frequency(50)
        Servo(pca, 0).move_to(0)
        assert pca_bus.counts(0)[1] == 205 and pca_bus.errors == []
        oled_bus = FakeSSD1306Bus()
        panel = SSD1306(oled_bus)
        panel.init()
        panel.show(np.eye(64, 128, dtype=bool))
        assert (oled_bus.frame() == np.eye(64, 128, dtype=bool)).all()
        for call, module in ((lambda: open_bus(1), "smbus2"), (lambda: render_text(["cork 0.93"]), "PIL"),
                             (lambda: oled_bus.save_png("never.png"), "PIL")):
            try:
                call()
                raise SystemExit(f"no MissingExtraError without {module}")
            except tofmat.MissingExtraError as e:
                assert (e.module, e.extra) == (module, "hw"), (e.module, e.extra)
                print(e)
        """
    ))  # fmt: skip
    assert blocked.attempts() == ["smbus2", "PIL", "PIL"]
    assert not (blocked.workdir / "never.png").exists()
    p = ok(blocked.python(
        """
        from tofmat.hw import open_bus
        try:
            open_bus(1)
        except ImportError as e:
            print(e)
        """
    ))  # fmt: skip
    assert p.stdout.strip() == "tofmat.hw.open_bus (a real I2C bus) needs smbus2: pip install 'tofmat[hw]'"
    assert blocked.attempts() == ["smbus2"]


def test_require_imports_or_names_the_extra(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert require("json.decoder", extra="sim", feature="x").__name__ == "json.decoder"
    with pytest.raises(MissingExtraError) as e:
        require("tofmat_no_such_module.sub", extra="plot", feature="drawing")
    assert str(e.value) == "drawing needs tofmat_no_such_module: pip install 'tofmat[plot]'"
    # Installed but broken (a failing import inside it): the reason is in the message.
    (tmp_path / "tofmat_broken_dep.py").write_text("raise ImportError('libfoo.so: cannot open shared object file')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(MissingExtraError) as e:
        require("tofmat_broken_dep", extra="sim", feature="fitting")
    assert str(e.value) == ("fitting needs tofmat_broken_dep (tofmat_broken_dep is installed but does not import: "
                            "libfoo.so: cannot open shared object file): pip install 'tofmat[sim]'")  # fmt: skip
    sys.modules.pop("tofmat_broken_dep", None)


# --- the package metadata --------------------------------------------------------------------


def requirement_name(req: str) -> str:
    m = re.match(r"[A-Za-z0-9._-]+", req.strip())
    assert m, req
    return m.group(0).lower()


def test_pyproject_core_and_extras() -> None:
    project = tomllib.loads((SDK / "pyproject.toml").read_text())["project"]
    assert [requirement_name(r) for r in project["dependencies"]] == CORE
    extras = {k: {requirement_name(r) for r in v} for k, v in project["optional-dependencies"].items()}
    assert extras == EXTRAS
    assert extras["all"] == extras["sim"] | extras["plot"] | extras["hw"] | extras["learn"]
    # The pinned dev/test set (make setup) still installs everything, extras included.
    pinned = {requirement_name(ln) for ln in (SDK / "requirements.txt").read_text().splitlines() if ln.strip()
              and not ln.startswith("#")}  # fmt: skip
    assert set(CORE) | extras["all"] <= pinned


def test_every_require_names_an_extra_that_installs_the_module() -> None:
    """Each require(module, extra=...) in the package: the extra exists and lists that module."""
    optional = tomllib.loads((SDK / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    extras = {k: {requirement_name(r) for r in v} for k, v in optional.items()}
    seen = []
    for path in (SDK / "tofmat").rglob("*.py"):
        if path.name == "_extras.py":  # the helpers themselves
            continue
        tree = ast.parse(path.read_text())
        for node in tree.body:  # module level: never an import of an extra
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module or ""] if isinstance(node, ast.ImportFrom) else [])  # fmt: skip
            assert not [n for n in names if n.split(".")[0] in BLOCKED], f"{path}:{node.lineno}"
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)):
                continue
            kw = {k.arg: k.value for k in node.keywords}
            if node.func.id == "require" and node.args and isinstance(node.args[0], ast.Constant):
                module = str(node.args[0].value).split(".")[0]
            elif node.func.id == "require_pyplot":
                module = "matplotlib"
            else:
                continue
            extra, where = kw["extra"], f"{path}:{node.lineno}"
            assert isinstance(extra, ast.Constant), f"{where}: extra must be a literal"
            dist = DISTRIBUTION.get(module, module).lower()
            assert dist in extras.get(str(extra.value), set()), f"{where}: {dist} is not in [{extra.value}]"
            seen.append((path.name, module))
    assert {("cli.py", "matplotlib"), ("calibrate.py", "scipy"), ("plot.py", "matplotlib"), ("bus.py", "smbus2"),
            ("ssd1306.py", "PIL"), ("fake_ssd1306.py", "PIL")} <= set(seen)  # fmt: skip
