"""The README's Python example is a doctest: it prints what the README shows."""

from __future__ import annotations

import doctest
import re
from pathlib import Path

README = Path(__file__).resolve().parents[2] / "README.md"


def test_the_readme_python_example_prints_what_it_shows() -> None:
    text = README.read_text("utf-8")
    blocks = re.findall(r"^```pycon\n(.*?)^```$", text, flags=re.DOTALL | re.MULTILINE)
    assert any("run_simulation(" in block for block in blocks), (
        "the README's run_simulation example is not a ```pycon block of >>> lines any more"
    )
    for block in blocks:
        line = text[: text.index(block)].count("\n")
        example = doctest.DocTestParser().get_doctest(block, {}, "README.md", str(README), line)
        report: list[str] = []
        result = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS).run(example, out=report.append)
        assert result.attempted and not result.failed, "".join(report)
