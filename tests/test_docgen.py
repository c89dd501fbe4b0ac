"""Generated blocks in docs/ (sim.docgen) are in step with the code."""

import pytest

from sim.docgen import BLOCK, render, stale_blocks


def test_every_generated_block_in_the_docs_is_current():
    assert stale_blocks() == []


def test_a_stale_block_is_found_and_rewritten():
    text = "intro\n<!-- generated: run-modes -->\nan old table\n<!-- end generated -->\nafter\n"
    fresh = render(text)
    assert "an old table" not in fresh and "`momentum-guarded`" in fresh
    assert fresh.startswith("intro\n") and fresh.endswith("<!-- end generated -->\nafter\n")
    assert render(fresh) == fresh
    assert len(BLOCK.findall(fresh)) == 1


def test_an_unknown_block_is_named():
    with pytest.raises(KeyError, match="no generator for block 'nonsense'"):
        render("<!-- generated: nonsense -->\nx\n<!-- end generated -->\n")
