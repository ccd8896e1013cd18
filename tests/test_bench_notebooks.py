"""benchmarks/bench_notebooks.py times each code cell of a notebook from what its kernel records."""

import importlib.util
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_notebooks.py"


def test_each_code_cell_is_timed_in_a_fresh_kernel(tmp_path):
    import nbformat

    spec = importlib.util.spec_from_file_location("bench_notebooks", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    notebook = nbformat.v4.new_notebook()
    notebook.cells = [
        nbformat.v4.new_markdown_cell("A markdown cell is not counted."),
        nbformat.v4.new_code_cell("import time\ntime.sleep(0.5)"),
        nbformat.v4.new_code_cell("x = 1"),
    ]
    path = tmp_path / "timed.ipynb"
    nbformat.write(notebook, path)
    timed = module.run(path, {}, tmp_path / "k")
    assert [k for k, _, _ in timed] == [0, 1]  # numbered among code cells, as nbval does
    assert timed[0][2] == "import time"
    assert 0.5 <= timed[0][1] < 10
    assert timed[1][1] < 0.5
