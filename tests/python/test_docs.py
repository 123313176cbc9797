"""The Python examples of the README and of docs/ run against the installed module, in the
order they appear in their file (a later block may use what an earlier one made), in a scratch
folder beside the repository's data/. A block marked ``<!-- check: parse-only ... -->`` (it needs
a Dask cluster) is compiled only; one marked ``<!-- check: slow ... -->`` (a whole fit and
diagnosis) runs with the slow checks (``ITAIPU_SLOW_TESTS=1``). CSV blocks are job tables that
``itaipu_calib.fleet.jobs_from_csv`` must read. The shell, TOML and Rust examples are checked by
crates/cli/tests/docs.rs."""

import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FILES = [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))
SLOW = bool(os.environ.get("ITAIPU_SLOW_TESTS"))


def _blocks(path):
    """(line, language, check, text) of every fenced block of a Markdown file."""
    lines = path.read_text().splitlines()
    out, k = [], 0
    while k < len(lines):
        m = re.match(r"^```(\w*)", lines[k])
        if not m:
            k += 1
            continue
        before = [l for l in lines[:k] if l.strip()]
        check = None
        if before and before[-1].strip().startswith("<!-- check:"):
            check = before[-1].strip()[len("<!-- check:"):-len("-->")].strip()
        start, k = k, k + 1
        body = []
        while k < len(lines) and not lines[k].startswith("```"):
            body.append(lines[k])
            k += 1
        out.append((start + 1, m.group(1), check, "\n".join(body) + "\n"))
        k += 1
    return out


def _python_files():
    return [f for f in FILES if any(lang == "python" for _, lang, _, _ in _blocks(f))]


@pytest.mark.parametrize("path", _python_files(), ids=lambda p: p.name)
def test_python_examples_run(path, tmp_path, monkeypatch):
    (tmp_path / "data").symlink_to(ROOT / "data")
    (tmp_path / "out").mkdir()
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "__docs__"}
    ran = 0
    for line, lang, check, text in _blocks(path):
        if lang != "python":
            continue
        code = compile(text, f"{path.name}:{line}", "exec")
        if check and check.startswith("parse-only"):
            continue
        if check and check.startswith("slow") and not SLOW:
            continue
        exec(code, namespace)
        ran += 1
    assert ran or not SLOW


def test_job_tables_read():
    from itaipu_calib.fleet import jobs_from_csv
    n = 0
    for path in FILES:
        for line, lang, _, text in _blocks(path):
            if lang != "csv":
                continue
            table = Path(os.environ.get("TMPDIR", "/tmp")) / f"itaipu-docs-{os.getpid()}-{line}.csv"
            table.write_text(text)
            try:
                jobs = jobs_from_csv(table)
            finally:
                table.unlink()
            assert jobs, f"{path.name}:{line}"
            n += 1
    assert n >= 1
