"""Processes import what they use, no more (issue 47): the runner's figure process draws Figure 2 without torch (its
import cost ~1 CPU-s on the core beside the runner's own), unless it will run the run's population; the library's
package gives its names when asked, so a torch-free module of it (aesop_torch.names) stays torch-free. Each import
is checked in a fresh interpreter: the test process has torch already."""

import subprocess
import sys
from pathlib import Path

import pytest

import aesop_torch
from aesop_torch import encoders, names, rules

ROOT = Path(__file__).resolve().parents[1]


def fresh(code: str) -> list[str]:
    """The lines `code` prints in a fresh interpreter run from the repository's root."""
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          check=False)
    assert done.returncode == 0, done.stderr
    return done.stdout.split()


def test_the_figure_process_imports_torch_only_to_run_a_population():
    loaded = "'torch' in __import__('sys').modules"
    prepared = "list(__import__('train.learning.population', fromlist=['_']).__dict__.get('_PREPARED', {'-': 0}))"
    out = fresh("from train.runner.figure_process import Drawer\n"
                "for population in (None, (3, 'all', 0)):\n"
                "    d = Drawer(population)\n"
                f"    print(d.draw('builtins:eval', {loaded!r}).get(timeout=60))\n"
                f"    print(d.draw('builtins:eval', {prepared!r}).get(timeout=60) if population else '')\n"
                "    d.close()\n"
                f"print({loaded})\n")
    # the figure alone; with the population (its orders prepared); the runner itself untouched
    assert out == ["False", "True", "[(3,", "'all',", "0)]", "False"]


def test_the_names_module_and_the_figures_are_torch_free():
    assert fresh("import sys, aesop_torch.names, train.runner.figures; print('torch' in sys.modules)") == ["False"]


def test_the_package_imports_a_name_when_it_is_asked_for():
    assert fresh("import sys, aesop_torch; a = 'torch' in sys.modules; from aesop_torch import Agent; "
                 "print(a, 'torch' in sys.modules, Agent.__module__)") == ["False", "True", "aesop_torch.agent"]
    for name in aesop_torch.__all__:   # every name it lists, from the module that defines it
        assert getattr(aesop_torch, name) is getattr(sys.modules[f"aesop_torch.{aesop_torch._WHERE[name]}"], name)
    assert set(aesop_torch.__all__) <= set(dir(aesop_torch))
    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        aesop_torch.Nope   # noqa: B018


def test_the_names_are_the_ones_the_library_uses():
    assert encoders.PROPERTIES is rules.PROPERTIES is names.PROPERTIES == ("color", "shape", "size", "weight")
    assert encoders.OBJECT_PROPERTIES is names.OBJECT_PROPERTIES and rules.STATES is names.STATES
    assert len(rules.KNOWLEDGE_LETTERS) == len(names.STATES)
    assert encoders.object_properties({"weight": 1, "width": 2, "color": 3}) == ("color", "weight")


def test_the_collector_is_off_while_the_runner_imports_and_on_in_what_it_forks():
    out = fresh("import gc\n"
                "from train.common.collector import imports_begin, imports_done\n"
                "from train.learning.sim_pool import by_name, end_pool, quiet_pool\n"
                "imports_done()\n"   # the collector was on: nothing frozen
                "print(gc.isenabled(), gc.get_freeze_count())\n"
                "imports_begin()\n"
                "pool = quiet_pool(1, None)\n"   # forked while it is off: on in the child
                "print(gc.isenabled(), pool.apply_async(by_name, ('gc:isenabled', ())).get(timeout=60))\n"
                "end_pool(pool)\n"
                "imports_done()\n"
                "print(gc.isenabled(), gc.get_freeze_count() > 0)\n")
    assert out == ["True", "0", "False", "True", "True", "True"]
