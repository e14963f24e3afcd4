"""Issue 33 item 1: credcli in Jupyter, tested by executing a real notebook
(docs/notebooks/quickstart.ipynb) in a real kernel and reading its outputs."""

from __future__ import annotations

from pathlib import Path

import pytest

nbclient = pytest.importorskip("nbclient")
nbformat = pytest.importorskip("nbformat")
pytest.importorskip("ipykernel")

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOK = ROOT / "docs" / "notebooks" / "quickstart.ipynb"


@pytest.fixture(scope="module")
def cells():
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    client = nbclient.NotebookClient(
        notebook, timeout=120, kernel_name="python3", resources={"metadata": {"path": str(ROOT)}}
    )
    client.execute()
    return [c for c in notebook.cells if c.cell_type == "code"]


def _output(cell, mime: str) -> str:
    for out in cell.outputs:
        if out.output_type == "error":
            raise AssertionError("".join(out.traceback))
        if out.output_type in ("execute_result", "display_data") and mime in out.data:
            return out.data[mime]
        if mime == "stdout" and out.output_type == "stream" and out.name == "stdout":
            return out.text
    return ""


def test_results_show_as_a_coloured_table_with_the_advice(cells):
    html = _output(cells[1], "text/html")
    assert "<table>" in html and html.count("<tr>") == 3  # header, right, too-small
    assert 'style="color: #176f2c; font-weight: 600">credible<' in html
    assert 'style="color: #a33a00; font-weight: 600">optimism<' in html
    assert "multiply" in html.lower() or "covariance" in html.lower()  # the advice line
    assert _output(cells[2], "text/plain").count("Label.") == 2


def test_one_diagnosis_and_monte_carlo_show_as_tables(cells):
    assert ">optimism<" in _output(cells[3], "text/html")
    monte_carlo = _output(cells[6], "text/html")
    assert "8 runs; per-epoch ANEES inside its 95% interval" in monte_carlo


def test_the_text_table_is_captured_not_displayed(cells):
    """In Jupyter, Rich showed the table in the notebook and returned '' (2,574
    characters in plain Python); the assertion message lost its table."""
    printed = _output(cells[4], "stdout")
    assert "too-small" in printed and "optimism" in printed and len(printed) > 500
    assert not [o for o in cells[4].outputs if o.output_type == "display_data"]
    first, length = _output(cells[5], "stdout"), int(_output(cells[5], "text/plain"))
    assert first.startswith("not credible at α = 0.05: too-small: optimism") and length > 500
    assert not [o for o in cells[5].outputs if o.output_type == "display_data"]
