"""The notebooks run top to bottom without errors, each within its time budget, and are stored without outputs."""

import time

import nbformat
import pytest
from conftest import ROOT
from nbclient import NotebookClient

NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
BUDGET_S = 60  # per notebook on a 2-core CPU (the limit)


def _widget_outputs(nb) -> list[dict]:
    """Outputs held by Output widgets (ipywidgets' `interact` draws into one), from the saved widget state."""
    state = nb.metadata.get("widgets", {}).get("application/vnd.jupyter.widget-state+json", {}).get("state", {})
    return [o for model in state.values() for o in model.get("state", {}).get("outputs", [])]


def test_there_are_notebooks():
    assert len(NOTEBOOKS) >= 1


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_is_stored_without_outputs(path):
    nb = nbformat.read(path, as_version=4)
    for cell in nb.cells:
        if cell.cell_type == "code":
            assert cell.outputs == [] and cell.execution_count is None, f"{path.name}: strip outputs before committing"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, tmp_path, monkeypatch):
    monkeypatch.setenv("PYTHONPATH", str(ROOT))
    monkeypatch.setenv("DIFFWASH_CACHE_DIR", "off")
    # The kernel picks matplotlib's inline backend only when MPLBACKEND is unset (Agg would hide every figure).
    monkeypatch.delenv("MPLBACKEND", raising=False)
    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(nb, timeout=BUDGET_S * 2, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}})
    start = time.perf_counter()
    client.execute()
    elapsed = time.perf_counter() - start
    errors = [o for c in nb.cells for o in c.get("outputs", []) if o.get("output_type") == "error"]
    assert not errors
    # With ipywidgets installed, an interact callback's output (and its errors) lives in an Output widget.
    assert not [o for o in _widget_outputs(nb) if o.get("output_type") == "error"], "an error inside a widget"
    images = sum("image/png" in o.get("data", {}) for c in nb.cells for o in c.get("outputs", []))
    assert images >= 1, "a notebook should show its results as figures"
    assert elapsed < BUDGET_S, f"{path.name} took {elapsed:.0f} s; slowest cells: {_slowest_cells(nb)}"


def _slowest_cells(nb, n: int = 3) -> str:
    """The cells that took longest, from nbclient's timing metadata (to say where a slow run went)."""
    from datetime import datetime

    times = []
    for i, c in enumerate(nb.cells):
        ex = c.get("metadata", {}).get("execution", {})
        if "iopub.execute_input" in ex and "shell.execute_reply" in ex:
            t0, t1 = (datetime.fromisoformat(ex[k].replace("Z", "+00:00")) for k in ("iopub.execute_input", "shell.execute_reply"))
            times.append(((t1 - t0).total_seconds(), i))
    return ", ".join(f"cell {i}: {t:.0f} s" for t, i in sorted(times, reverse=True)[:n])


def test_library_figures_leave_the_callers_matplotlib_backend_alone(monkeypatch, tmp_path):
    """Drawing a report in a notebook must not switch its inline backend (later cells would show no figures)."""
    import matplotlib
    import matplotlib.pyplot as plt

    from diffwash import pigments
    from diffwash.fit import fit_swatches, parse_layout
    from diffwash.fit import save_swatch_report
    from diffwash.swatchcard import make_swatch_card

    def switch(*args, **kwargs):
        raise AssertionError("the library switched matplotlib's backend")

    monkeypatch.setattr(matplotlib, "use", switch)
    monkeypatch.setattr(plt, "switch_backend", switch)
    open_figures = plt.get_fignums()
    card = make_swatch_card(pigments.load("Cerulean Blue"), coats=(1, 2), seed=3)
    fit = fit_swatches(card.photo, card.layout)
    save_swatch_report(tmp_path / "report.png", fit, card.photo, parse_layout(card.layout))
    assert (tmp_path / "report.png").stat().st_size > 0
    assert plt.get_fignums() == open_figures  # and no pyplot figure left open
    # The demo's report and the swatch chart: no module of the package switches backends (the CLI picks Agg
    # through MPLBACKEND, for itself).
    for path in (ROOT / "diffwash").rglob("*.py"):
        text = path.read_text()
        assert "matplotlib.use(" not in text and "switch_backend(" not in text, path
