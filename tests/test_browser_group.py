"""The README's test command runs the browser tests one after another on one worker (tests/conftest.py): checked on
a suite of its own, run as the README runs the real one. It once did not: the conftest's hook marked the tests after
xdist had read the marks, and pytest 9.2 stopped honouring the group at all (pytest-dev/pytest-xdist#1386)."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_browser_tests_run_on_one_worker_and_the_others_on_both(tmp_path):
    (tmp_path / "conftest.py").write_text("from tests.conftest import pytest_collection_modifyitems  # noqa: F401\n")
    (tmp_path / "test_suite.py").write_text(textwrap.dedent("""
        import os, pathlib, time, pytest

        def _ran(kind, i):
            time.sleep(0.3)
            pathlib.Path(os.environ["SEEN_DIR"], f"{kind}-{i}").write_text(os.environ["PYTEST_XDIST_WORKER"])

        @pytest.fixture
        def browser():
            return None

        @pytest.mark.parametrize("i", range(6))
        def test_in_a_browser(browser, i):
            _ran("browser", i)

        @pytest.mark.parametrize("i", range(6))
        def test_elsewhere(i):
            _ran("other", i)
    """))
    seen_dir = tmp_path / "seen"
    seen_dir.mkdir()
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-s", "-p", "no:cacheprovider", "-n", "2",
                          "--dist", "loadgroup", "-c", os.devnull, "--rootdir", str(tmp_path), str(tmp_path)],
                         capture_output=True, text=True, timeout=120, cwd=tmp_path,
                         env={**os.environ, "PYTHONPATH": str(ROOT), "SEEN_DIR": str(seen_dir)})
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    seen = {path.name: path.read_text() for path in seen_dir.iterdir()}
    assert len(seen) == 12, seen
    assert len({worker for name, worker in seen.items() if name.startswith("browser")}) == 1, seen
