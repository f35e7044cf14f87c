"""The README's promises: its Python example runs as written, its two commands are the tox
environments CI and a newcomer run, its links lead to files, and it stays short and free of
the project's history (commit hashes, issue numbers)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
#: the pages a user reads first: no history there (the reports and CHANGELOG.md keep it)
USER_PAGES = ["README.md", "docs/index.md", "docs/getting-started.md", "docs/choosing.md",
              "docs/guide/own-problem.md"]


def _blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", README, flags=re.DOTALL)


def test_the_python_example_runs_as_written(tmp_path):
    (code,) = _blocks("python")
    run = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-4000:]
    assert "stress_ratio" in run.stdout
    assert (tmp_path / "out" / "element" / "summary.json").is_file()
    assert run.stderr.count("Warp") == 0  # no warp banner or CUDA warning on the CPU


def test_the_two_commands_are_the_tox_environments_ci_runs():
    (commands,) = _blocks("bash")
    lines = [ln for ln in commands.splitlines() if ln and not ln.startswith("#")]
    assert lines == ["python -m pip install tox && tox -e run",
                     "python -m pip install tox && tox -e py"]
    tox = (ROOT / "tox.ini").read_text(encoding="utf-8")
    assert "[testenv:run]" in tox and re.search(r"^envlist = py\b", tox, flags=re.MULTILINE)
    assert "tox -e py" in (ROOT / ".ci" / "run").read_text(encoding="utf-8")


def test_links_lead_to_files():
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", README)
    local = [t for t in targets if not re.match(r"[a-z]+://", t)]
    assert local and not [t for t in local if not (ROOT / t).exists()]


def test_short_and_without_history():
    assert len(README.splitlines()) <= 120
    for page in USER_PAGES:
        text = (ROOT / page).read_text(encoding="utf-8")
        assert not re.search(r"\bissues? #?\d+", text, flags=re.IGNORECASE), page
        hashes = [h for h in re.findall(r"\b[0-9a-f]{7,40}\b", text) if re.search(r"[a-f]", h)
                  and re.search(r"\d", h)]
        assert not hashes, (page, hashes)
