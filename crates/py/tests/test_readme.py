"""Every ```python block of the repository README runs, in order, in a fresh directory.

Blocks share one namespace (a later block may use names of an earlier one), like a reader
pasting them into one interpreter session.
"""

from __future__ import annotations

import pathlib
import re

import pytest

README = pathlib.Path(__file__).resolve().parents[3] / "README.md"
BLOCK = re.compile(r"^```python\n(.*?)^```", re.MULTILINE | re.DOTALL)


def python_blocks() -> list[str]:
    if not README.is_file():
        return []
    return BLOCK.findall(README.read_text(encoding="utf-8"))


def test_readme_has_python_examples():
    assert python_blocks(), f"no ```python blocks in {README}"


def test_readme_examples_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, object] = {"__name__": "__readme__"}
    for k, code in enumerate(python_blocks()):
        try:
            exec(compile(code, f"README.md python block {k + 1}", "exec"), namespace)
        except Exception as e:  # noqa: BLE001 - re-raised with the block number
            pytest.fail(f"README python block {k + 1} failed: {type(e).__name__}: {e}")
