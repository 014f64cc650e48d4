"""Every ```python block of the README and of docs/python.md runs, in order, in a fresh directory.

The blocks of a page share one namespace (a later block may use names of an earlier one), like a
reader pasting them into one interpreter session.
"""

from __future__ import annotations

import pathlib
import re

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[3]
PAGES = ["README.md", "docs/python.md"]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.MULTILINE | re.DOTALL)


def python_blocks(page: str) -> list[str]:
    path = ROOT / page
    if not path.is_file():
        return []
    return BLOCK.findall(path.read_text(encoding="utf-8"))


@pytest.mark.parametrize("page", PAGES)
def test_page_has_python_examples(page):
    assert python_blocks(page), f"no ```python blocks in {ROOT / page}"


@pytest.mark.parametrize("page", PAGES)
def test_page_examples_run(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, object] = {"__name__": "__readme__"}
    for k, code in enumerate(python_blocks(page)):
        try:
            exec(compile(code, f"{page} python block {k + 1}", "exec"), namespace)
        except Exception as e:  # noqa: BLE001 - re-raised with the block number
            pytest.fail(f"{page} python block {k + 1} failed: {type(e).__name__}: {e}")
