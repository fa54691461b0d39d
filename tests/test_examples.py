"""Every notebook in examples/ runs, at reduced size, so that none breaks silently,
and shows its figures. Its first code cell holds the size parameters; the test
replaces it. In a notebook, jaxchain's progress bars are text, with no widget
library and no warning about one."""

import re
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"

#: Per notebook: its first code cell at reduced size, and a text its outputs print.
#: Where a test elsewhere runs the same scene, the sizes here are that test's, so that
#: the kernel finds the programs that test compiled in the session's persistent
#: compilation cache (tests/conftest.py), or leaves its own there for the test: 01
#: test_cli.py's `localized` run, 03 the `figure --quick` scenes of test_dynamics.py
#: (jaxchain/_cli/figure.py: QUICK), 06 test_mistuning.py's study, 07 test_snake.py's
#: ring of 4 started as `localized_branches` starts it by default (SNAKE_START: the
#: window [11500, 12000], a fraction of a second on 4 oscillators, cheaper than a
#: program of its own). In 08 the ensemble
#: and the branch's starting simulation share their options (T_END, TRANSIENT =
#: START_T_END, START_T_END - 500), so that they share one program.
SMALL = {
    "01_localized_states.ipynb":
        ("N_OSC = 3\nV_D = 1.5\nT_END = 400.0\nTRANSIENT = 200.0", "E / n_HALC"),
    "02_bifurcation_sweep.ipynb":
        ("N_OSC = 4\nVD_START, VD_STOP, N_VD = 1.0, 2.0, 3\nT_END = 400.0\n"
         "TRANSIENT = 200.0\nBATCH_SIZE = 5", "fronts at v_d ="),
    "03_dynamics_of_localized_states.ipynb":
        ("N_OSC = 8\nT_END = 600.0\nTRANSIENT = 400.0\nCHUNK = 50.0\nT_SERIES = 100.0",
         "the two signals agree on"),
    "04_basin_stability.ipynb":
        ("N_OSC = 3\nSAMPLES = 8\nVD_ONE = (1.0, 2.1, 2)\nSAMPLES_ONE = 8\n"
         "T_END, TRANSIENT = 300.0, 200.0", "basin stability of stick-slip"),
    "05_any_chain.ipynb":
        ("N_OSC = 4\nSIGMA, SEED = 0.01, 1\nV_D = 1.2\nT_END, TRANSIENT = 300.0, 200.0",
         "the stored chain rebuilds the same parameters: True"),
    "06_anderson_meets_friction.ipynb":
        ("N_OSC = 4\nSIGMAS = (0.0, 2.0)\nDRAWS = 2\nSAMPLES = 2\nV_D = (1.5,)\n"
         "T_END, TRANSIENT = 300.0, 200.0\nEDGE_T_END = 300.0\nFOLDS = 0\nCELLS = 20_000\n"
         "OUT = 'anderson'", "staircase kept"),
    "08_brake_pad.ipynb":
        ("ROWS, COLS = 2, 2\nV_D = 1.5\nT_END, TRANSIENT = 700.0, 200.0\nMAX_POINTS = 3\n"
         "START_T_END = 700.0\nSTARTS = ('corner',)\nRING = False", "kept"),
    "09_identification.ipynb":
        ("T_END = 20.0\nDT = 0.2\nSPEEDS = (0.3, 0.5, 0.7)\nNOISE = 0.005",
         "within their stated uncertainty"),
    "07_snaking.ipynb":
        ("N_OSC = 4\nSITES = (1,)\nMAX_POINTS = 5\nSTART_T_END = 12000.0\nCHECK = False",
         "trivial multiplier error"),
}
#: A cell that draws: it calls one of jaxchain's plot functions or plt.show().
PLOTTING = re.compile(r"\bplt\.show\(|\bjc\.plot_\w+\(")


#: Notebooks that take more than about 30 s even at reduced size, on 2 cores with a
#: cold compilation cache (each kernel compiles its programs afresh).
SLOW = {"03_dynamics_of_localized_states.ipynb", "04_basin_stability.ipynb",
        "06_anderson_meets_friction.ipynb", "07_snaking.ipynb", "08_brake_pad.ipynb",
        "09_identification.ipynb"}


#: The notebooks that run a whole study (02 to 09: 8 to 35 s each on 2 cores) run
#: with the studies (`study`: CI's step of its own, .ci/run), to keep the default
#: run within 10 minutes: on the machine of session 79 the default run took 724.6 s
#: with 02 to 07 in it. 01 (one simulation) stays.
STUDY = {"02_bifurcation_sweep.ipynb", "03_dynamics_of_localized_states.ipynb",
         "04_basin_stability.ipynb", "05_any_chain.ipynb",
         "06_anderson_meets_friction.ipynb", "07_snaking.ipynb", "08_brake_pad.ipynb",
         "09_identification.ipynb"}


#: The two longest (70 and 119 s in CI's study step) are also `long`: CI leaves them
#: out to keep its whole run within 45 minutes.
LONG = {"08_brake_pad.ipynb", "09_identification.ipynb"}


def _marks(name: str) -> tuple:
    return ((pytest.mark.slow,) if name in SLOW else ()) + (
        (pytest.mark.study,) if name in STUDY else ()) + (
        (pytest.mark.long,) if name in LONG else ())


@pytest.mark.parametrize("name", [
    pytest.param(name, marks=_marks(name))
    for name in sorted(p.name for p in EXAMPLES.glob("*.ipynb"))])
def test_notebook_runs_small_and_shows_its_figures(name, tmp_path, monkeypatch):
    nb = nbformat.read(EXAMPLES / name, as_version=4)
    assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code"), \
        "store notebooks with their outputs cleared"
    assert nb.cells[0].cell_type == "markdown" and "Fig." in nb.cells[0].source
    first = next(c for c in nb.cells if c.cell_type == "code")
    first.source, says = SMALL[name]
    monkeypatch.delenv("MPLBACKEND", raising=False)  # the kernel's own: inline
    NotebookClient(nb, timeout=600, kernel_name="python3",
                   resources={"metadata": {"path": str(tmp_path)}}).execute()
    text = "".join(o.get("text", "") for c in nb.cells for o in c.get("outputs", []))
    assert says in text
    plotting = [c for c in nb.cells if c.cell_type == "code" and PLOTTING.search(c.source)]
    assert plotting, "a notebook here reproduces a figure"
    for cell in plotting:
        assert any("image/png" in o.get("data", {}) for o in cell.outputs), \
            f"no figure shown by the cell:\n{cell.source}"


#: A notebook cell that imports every module of jaxchain and runs a simulation with
#: its bar (`progress=True`: three chunks), recording the warnings: tqdm.auto's
#: notebook bar warns (TqdmWarning, with the path of its file) in a kernel without
#: ipywidgets, once, when a module imports it.
BAR_CELL = """\
import importlib, pkgutil, warnings
from tqdm import TqdmWarning
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    import jaxchain as jc
    jc.configure()
    for module in pkgutil.walk_packages(jc.__path__, "jaxchain."):
        importlib.import_module(module.name)
    options = jc.SimulationOptions(t_end=3.0, transient=1.0, chunk_length=1.0)
    jc.simulate(jc.ChainParams(n_osc=1), jc.OutOfPhaseExcitation.eq8([True]),
                options=options, progress=True)
print("TqdmWarnings:", [str(w.message) for w in caught if issubclass(w.category, TqdmWarning)])
"""


def test_progress_bars_in_a_notebook_are_text_without_a_warning(tmp_path):
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(BAR_CELL)])
    NotebookClient(nb, timeout=300, kernel_name="python3",
                   resources={"metadata": {"path": str(tmp_path)}}).execute()
    outputs = nb.cells[0].outputs
    printed = "".join(o.text for o in outputs if o.output_type == "stream" and o.name == "stdout")
    assert "TqdmWarnings: []" in printed, printed
    assert [o.output_type for o in outputs if o.output_type != "stream"] == [], "a widget"
    bar = "".join(o.text for o in outputs if o.output_type == "stream" and o.name == "stderr")
    # tqdm's text bar, drawn when the run starts (it is cleared when it ends)
    assert "simulate:   0%|" in bar and "| 0/3 [" in bar and "chunk/s]" in bar, bar
    assert "TqdmWarning" not in bar
