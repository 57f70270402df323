"""train/run.py refuses bad input with one line on stderr, exit code 2, and writes nothing; one class of bad input
per test (objects file, its bounds, flags, --out, a busy --out), and Ctrl-C ends in one line."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from in_process import run_main

ROOT = Path(__file__).resolve().parents[1]
GOOD = {"name": "red_heavy_cylinder", "shape": "cylinder", "color": "red", "dims_cm": [6.36, 11.5], "mass_g": 420}


def run(*args, cwd=None):
    """The script in its own process: for what only a process shows (--help's exit, a hang under a timeout, a
    display); the refusals call its main() in this process (run_main), the same code without the interpreter."""
    return subprocess.run([sys.executable, str(ROOT / "train" / "run.py"), *args], capture_output=True, text=True,
                          cwd=cwd, timeout=120)


def refused(tmp_path, objects_text, *words):
    f = tmp_path / "objects.json"
    f.write_text(objects_text)
    out = tmp_path / "out"
    r = run_main("--objects", str(f), "--out", str(out))
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1, r.stderr
    for w in words:
        assert w in lines[0], lines[0]
    assert "Traceback" not in r.stderr and r.stdout == ""
    assert not out.exists()  # nothing written
    return lines[0]


def obj(**kw):
    return {**GOOD, **kw}


@pytest.mark.parametrize("train, words", [
    ([obj(shape="pyramid")], ["red_heavy_cylinder", "shape"]),
    ([obj(dims_cm=[6.36])], ["red_heavy_cylinder", "dims_cm"]),
    ([obj(mass_g=0)], ["red_heavy_cylinder", "mass_g"]),
    ([obj(mass_g=-3)], ["red_heavy_cylinder", "mass_g"]),
    ([obj(dims_cm=[20.0, 5.0])], ["red_heavy_cylinder", "dims_cm"]),      # wider than the jar
    ([obj(), obj()], ["red_heavy_cylinder", "name"]),                     # duplicate names
    ([obj(color="octarine")], ["red_heavy_cylinder", "color"]),
    ([obj(color=[1.2, 0, 0])], ["red_heavy_cylinder", "color"]),
])
def test_bad_object_is_refused(tmp_path, train, words):
    refused(tmp_path, json.dumps({"train": train}), *words)


def test_malformed_json_is_refused(tmp_path):
    refused(tmp_path, '{"train": [', "JSON")


def test_non_finite_number_is_refused(tmp_path):
    refused(tmp_path, '{"train": [{"name": "a", "shape": "cube", "color": "red", "dims_cm": [1e999], "mass_g": 5}]}',
            "a", "dims_cm")


def test_water_deeper_than_jar_is_refused(tmp_path):
    jar = {"inner_diameter_cm": 12.0, "height_cm": 20.0, "water_depth_cm": 25.0}
    refused(tmp_path, json.dumps({"jar": jar, "train": [GOOD]}), "jar", "water_depth_cm")


def test_bad_flags_are_refused(tmp_path):
    for args in (["--orders", "zero"], ["--orders", "0"], ["--seed", "-1"], ["--resume"], ["--bogus"]):
        r = run_main(*args, "--out", str(tmp_path / "o"))
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, (args, r.stderr)
        assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("args, words", [
    (["--model", "bayes"], ["--model", "bayes"]),
    (["--ablate", "prior"], ["--ablate prior", "paper", "rules, gating"]),            # the paper model has no prior
    (["--model", "extended", "--ablate", "memory"], ["--ablate memory", "extended", "prior"]),
])
def test_a_model_or_ablation_it_does_not_have_is_refused(tmp_path, args, words):
    r = run_main(*args, "--out", str(tmp_path / "o"))
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert all(w in lines[0] for w in words), lines[0]
    assert not (tmp_path / "o").exists()


def test_resume_without_checkpoint_and_occupied_out_are_refused(tmp_path):
    r = run_main("--out", str(tmp_path / "none"), "--resume")
    assert r.returncode == 2 and "no checkpoint" in r.stderr
    occupied = tmp_path / "occupied"
    occupied.mkdir()
    (occupied / "summary.json").write_text("{}")
    r = run_main("--out", str(occupied))
    assert r.returncode == 2 and "already holds" in r.stderr
    assert (occupied / "summary.json").read_text() == "{}"  # an earlier run is never damaged


def test_gui_without_a_display_is_refused_instead_of_hanging(tmp_path, monkeypatch):
    # pybullet's GUI with no X display does not fail, it hangs: the runner must say so before anything is written
    monkeypatch.delenv("DISPLAY", raising=False)
    r = run("--gui", "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "DISPLAY" in r.stderr, r.stderr
    assert not (tmp_path / "o").exists()


def test_gui_with_a_display_no_x_server_answers_is_refused_instead_of_hanging(tmp_path, monkeypatch):
    # DISPLAY set, nobody listening: pybullet printed "cannot connect to X server" and hung, deaf to SIGTERM
    display = ":4917"
    assert not Path(f"/tmp/.X11-unix/X{display[1:]}").exists()
    monkeypatch.setenv("DISPLAY", display)
    r = run("--gui", "--out", str(tmp_path / "o"))
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and lines[0].startswith("train/run.py: error: --gui:"), r.stderr
    assert "':4917'" in r.stderr or "libX11" in r.stderr, r.stderr
    assert not (tmp_path / "o").exists()


# -- bounds on the objects file: every one refused in one line, before anything is read without bound -----------------

def test_huge_integer_is_refused(tmp_path):
    refused(tmp_path, '{"train": [{"name": "a", "shape": "cube", "color": "red", "dims_cm": [5], "mass_g": '
            + "9" * 400 + "}]}", "400 digits")


def test_deep_nesting_is_refused(tmp_path):
    refused(tmp_path, '{"train": ' + "[" * 200_000 + "]" * 200_000 + "}", "nests", "200001")


def test_oversized_file_is_refused(tmp_path):
    refused(tmp_path, json.dumps({"train": [GOOD], "_comment": "x" * 1_000_001}), "larger than 1,000,000 bytes")


def test_device_file_and_pipe_are_refused_not_read_forever(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)   # no writer: opening it for reading would wait for ever
    for objects in ("/dev/zero", str(fifo)):
        r = run("--objects", objects, "--out", str(tmp_path / "o"))
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "not a regular file" in r.stderr
        assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("name", ["evil\n", "x" * 65, "../up", "", "caf\u00e9"])
def test_bad_names_are_refused(tmp_path, name):
    refused(tmp_path, json.dumps({"train": [obj(name=name)]}), "field 'name'", "64")


def test_a_64_character_name_is_accepted():
    from sim.objects import parse_objects
    assert parse_objects({"train": [obj(name="x" * 64)]}).train[0].name == "x" * 64


# -- flags ----------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("args, words", [
    (["--orders", "\u00b2"], "--orders"),                # str.isdigit() accepts a superscript two
    (["--orders", "\u0663"], "--orders"),                # an Arabic-Indic three: int() would accept it
    (["--orders", "1000000000"], "1,000,000"),
    (["--orders", "1000001"], "1,000,000"),
    (["--orders", " 4"], "--orders"),
    (["--seed", "18446744073709551616"], "2**63"),
    (["--seed", "9223372036854775808"], "2**63"),
    (["--seed", "1e3"], "--seed"),
    (["--seed", "9" * 5000], "--seed"),
])
def test_out_of_range_flags_are_refused(tmp_path, args, words):
    r = run_main(*args, "--out", str(tmp_path / "o"))
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and words in lines[0], r.stderr
    assert r.stdout == "" and not (tmp_path / "o").exists()


def test_all_orders_of_too_many_objects_are_refused(tmp_path):
    many = [obj(name=f"o{i}") for i in range(10)]   # 10! = 3,628,800 orders
    f = tmp_path / "many.json"
    f.write_text(json.dumps({"train": many}))
    r = run_main("--objects", str(f), "--orders", "all", "--out", str(tmp_path / "o"))
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "10!" in lines[0] and "--orders N" in lines[0], r.stderr
    assert not (tmp_path / "o").exists()


# -- --out: not a directory we may write, or owned by another run -----------------------------------------------------

def test_out_that_cannot_be_a_directory_is_refused(tmp_path):
    (tmp_path / "afile").write_text("mine")
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    for out, words in ((tmp_path / "afile", "not a directory"), (tmp_path / "afile" / "sub", "not a directory"),
                       (tmp_path / "dangling", "symbolic link"), (tmp_path / "dangling" / "sub", "symbolic link")):
        r = run_main("--out", str(out))
        lines = r.stderr.strip().splitlines()
        assert r.returncode == 2 and len(lines) == 1 and words in lines[0], (out, r.stderr)
        assert "Traceback" not in r.stderr and r.stdout == ""
    assert (tmp_path / "afile").read_text() == "mine" and not (tmp_path / "nowhere").exists()


@pytest.mark.skipif(not hasattr(os, "geteuid"), reason="POSIX permissions")
def test_unwritable_out_is_refused(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o555)
    # root may write anywhere; the runner asks os.access, which answers for the real uid: make that an ordinary
    # user's (the effective uid stays root, so the interpreter under /root can still start)
    as_user = {"preexec_fn": lambda: os.setreuid(65534, -1)} if os.geteuid() == 0 else {}
    for out in (locked, locked / "sub"):
        r = subprocess.run([sys.executable, str(ROOT / "train" / "run.py"), "--out", str(out)], capture_output=True,
                           text=True, timeout=60, **as_user)
        assert r.returncode == 2 and "not writable" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert list(locked.iterdir()) == []


def test_out_in_use_by_another_run_is_refused_and_left_alone(tmp_path):
    import fcntl
    out = tmp_path / "busy"
    out.mkdir()
    with open(out / ".lock", "w") as lock:     # what a running run holds
        lock.write("4242\n")
        lock.flush()
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        for args in ([], ["--resume"]):
            r = run_main("--out", str(out), *args)
            lines = r.stderr.strip().splitlines()
            assert r.returncode == 2 and len(lines) == 1 and "in use by another run (pid 4242)" in lines[0], r.stderr
        assert sorted(p.name for p in out.iterdir()) == [".lock"] and (out / ".lock").read_text() == "4242\n"


def test_ctrl_c_in_a_terminal_ends_with_one_line_workers_included(tmp_path):
    # SIGINT to the whole process group, as a terminal's Ctrl-C does: the simulation's worker processes get it too
    f = tmp_path / "objects.json"
    f.write_text(json.dumps({"train": [GOOD, obj(name="blue", color="blue")]}))
    out = tmp_path / "out"
    cmd = [sys.executable, str(ROOT / "train" / "run.py"), "--objects", str(f), "--orders", "listed", "--out", str(out)]
    # a terminal's foreground job takes Ctrl-C: SIGINT at its default disposition, whatever started this test (a
    # background job, nohup or a CI runner may have it ignored, and an ignored SIGINT is inherited through exec)
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    while "simulating" not in (line := p.stdout.readline()):
        assert line, p.stderr.read()
    time.sleep(0.1)   # the workers are simulating (forked before this line; a drop takes >= 0.15 s, two ~0.4 s)
    os.killpg(p.pid, signal.SIGINT)
    _, err = p.communicate(timeout=60)
    lines = err.strip().splitlines()
    assert p.returncode == 130 and len(lines) == 1 and "interrupted" in lines[0] and "--resume" in lines[0], err
    r = subprocess.run(cmd + ["--resume"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert len(json.loads((out / "summary.json").read_text())["runs"][0]["episodes"]) == 2


def test_everything_before_the_first_line_runs_without_torch(tmp_path):
    # the first line must come within a second: flags, the objects file and --out are checked before torch (about a
    # second to import) is loaded
    code = ("import sys; sys.path.insert(0, sys.argv[1]); from train import run; "
            "a = run.parse_args(['--out', sys.argv[2]]); o = run.load_objects_or_fail(a.objects); "
            "run.count_orders(len(o.train), a.orders); run.check_out(a.out, a.resume); "
            "print(sorted(m for m in ('torch', 'tensorboard', 'matplotlib') if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", code, str(ROOT), str(tmp_path / "o")], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0 and r.stdout.strip() == "[]", (r.stdout, r.stderr)


# -- the config: --config FILE.toml and --set KEY=VALUE, refused in one line before anything is written --------------

def config_refused(tmp_path, *args) -> str:
    out = tmp_path / "out"
    r = run_main("--orders", "listed", "--out", str(out), *args)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert not out.exists()   # nothing written
    assert r.stdout == ""     # refused before the first line: no "starting" for a run that never starts
    return lines[0]


@pytest.mark.parametrize("args, words", [
    (["--set", "rules.uncertain_decay=abc"],
     ["train/run.py: error: --set rules.uncertain_decay=abc: rules.uncertain_decay takes a number (float), got 'abc'"]),
    (["--set", "rules.bogus=1"], ["--set rules.bogus=1: unknown key rules.bogus (rules has: ", "uncertain_decay"]),
    (["--set", "memory.max_episodes=1.5"], ["memory.max_episodes takes an integer (int), got 1.5"]),
    (["--set", "recall_sharpness=[8]"], ["recall_sharpness takes a number (float), got [8]"]),
    (["--set", "recall_sharpness=true"], ["recall_sharpness takes a number (float), got true"]),
    (["--set", "recall_sharpness=0"], ["--set recall_sharpness=0: recall_sharpness:", "must be > 0"]),
    (["--set", "world.mass_noise_g=-1"], ["world.mass_noise_g takes a number (float) >= 0, got -1.0"]),
    (["--set", "world.tank.ball_diameter_cm=9"], ["world.tank.ball_diameter_cm", "does not fit"]),
    (["--set", "sensor.mass_noise_g=5"], ["unknown key sensor.mass_noise_g", "did you mean world.mass_noise_g"]),
    (["--set", "seed=-1"], ["--set seed=-1: seed takes an integer from 0 to 2**63 - 1, got -1"]),
    (["--set", "rules.uncertain_decay"], ["--set rules.uncertain_decay: expected KEY=VALUE"]),
])
def test_a_bad_set_is_refused_in_one_line(tmp_path, args, words):
    line = config_refused(tmp_path, *args)
    assert all(w in line for w in words), line


def test_a_bad_config_file_is_refused_in_one_line(tmp_path):
    files = {"malformed.toml": ("[rules\nuncertain_decay = 1\n", ["not valid TOML", "line 1"]),
             "unknown.toml": ("[rules]\nbogus = 1\n", ["unknown.toml: unknown key rules.bogus"]),
             "wrong_type.toml": ("[memory]\nmax_episodes = 1.5\n", ["wrong_type.toml: memory.max_episodes takes an "
                                                                     "integer (int), got 1.5"]),
             "model.toml": ('model = "bayes"\n', ["model takes one of paper, contextual, extended, got 'bayes'"])}
    for name, (text, words) in files.items():
        f = tmp_path / name
        f.write_text(text)
        line = config_refused(tmp_path, "--config", str(f))
        assert line.startswith(f"train/run.py: error: --config {f}") and all(w in line for w in words), line
    line = config_refused(tmp_path, "--config", str(tmp_path / "missing.toml"))
    assert line == f"train/run.py: error: --config {tmp_path / 'missing.toml'}: no such file"
    # a flag's value is checked as the flag's: --ablate prior is no part of the file's paper model
    (tmp_path / "paper.toml").write_text('model = "paper"\n')
    line = config_refused(tmp_path, "--config", str(tmp_path / "paper.toml"), "--ablate", "prior")
    assert "--ablate prior: not a part of the paper model" in line, line


def test_help_states_the_configs_order():
    r = run("--help")
    text = " ".join(r.stdout.split())
    assert r.returncode == 0 and "--config FILE.toml" in text and "--set KEY=VALUE" in text
    assert "the defaults, the --config file, each --set in the order given, then --model, --ablate and --seed" in text
    assert "when the file and a flag both give a value, the flag wins" in text


def test_the_config_round_trips_into_summary_and_resume_must_match_it(tmp_path):
    from train.runner.summary import git_commit
    objects = tmp_path / "objects.json"
    objects.write_text(json.dumps({"train": [GOOD, obj(name="blue", color="blue")]}))
    cfg = tmp_path / "c.toml"
    cfg.write_text('model = "extended"\nrecall_sharpness = 8\n[rules]\nuncertain_decay = 0.5\n'
                   '[world]\nmass_noise_g = 0.5\n')
    out = tmp_path / "out"
    args = ["--objects", str(objects), "--orders", "listed", "--out", str(out), "--config", str(cfg),
            "--set", "rules.uncertain_decay=1.0", "--set", "memory.max_recalls=none", "--model", "paper"]
    r = run_main(*args)
    assert r.returncode == 0, r.stderr
    summary = json.loads((out / "summary.json").read_text())
    c = summary["config"]
    assert summary["model"] == c["model"] == "paper"                 # --model over the file's extended
    assert c["compare_with"] == 1                                    # so the paper model's, not the extended one's
    assert c["recall_sharpness"] == 8.0                              # the file's
    assert c["rules"]["uncertain_decay"] == 1.0                      # --set over the file
    assert c["memory"]["max_recalls"] is None                        # "none"
    assert c["world"]["mass_noise_g"] == 0.5 and c["world"]["tank"]["water"]["density"] == 1000.0
    assert c["seed"] == summary["seed"] == 0 and c["memory"]["max_episodes"] == 2   # as the experiment ran it
    assert json.loads((out / "config.json").read_text()) == c
    assert summary["commit"] == git_commit() and summary["commit"] != ""
    assert set(summary["versions"]) == {"torch", "pybullet", "numpy"}
    # resuming with another config is refused, naming the first key that differs, and changes nothing
    before = (out / "summary.json").read_text()
    for other, word in ((["--set", "rules.uncertain_decay=0.9"], "rules.uncertain_decay"),
                        (["--set", "world.mass_noise_g=1"], "world.mass_noise_g"),
                        (["--model", "extended"], "model")):
        r = run_main(*args, *other, "--resume")
        lines = r.stderr.strip().splitlines()
        assert r.returncode == 2 and len(lines) == 1 and word in lines[0] and "--resume" in lines[0], r.stderr
        assert (out / "summary.json").read_text() == before


@pytest.mark.parametrize("kind", ["link", "dangling", "fifo"])
def test_a_lock_that_is_not_a_regular_file_is_refused_without_touching_anything(tmp_path, kind):
    """DIR/.lock as a symbolic link (to a file, or to nothing) or a FIFO: opened without following links or blocking,
    refused in one line; the link's target is neither overwritten nor created, and the run does not hang."""
    out, target = tmp_path / "out", tmp_path / "target.txt"
    out.mkdir()
    if kind == "fifo":
        os.mkfifo(out / ".lock")
    else:
        if kind == "link":
            target.write_text("precious\n")
        os.symlink(target, out / ".lock")
    r = run_main("--out", str(out))
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and ".lock" in lines[0] and "Traceback" not in r.stderr, r.stderr
    assert (target.read_text() == "precious\n") if kind == "link" else not target.exists()
    assert sorted(p.name for p in out.iterdir()) == [".lock"]


def test_the_runners_tables_of_models_and_ablations_are_the_agents():
    """train/common/models.py keeps a copy of them, to refuse a bad --model or --ablate before torch is imported
    (the runner's and the sweeps' one table)."""
    from aesop_torch.agent import ABLATIONS, MODELS
    from aesop_torch.exploration import EXPLORE
    from train.common import models
    assert models.MODELS == MODELS and models.ABLATIONS == ABLATIONS and models.EXPLORE == EXPLORE


# -- what the other commands say, and the console commands ------------------------------------------------------------

def test_ask_names_the_objects_file_it_refuses(tmp_path, capsys):
    from train.ask import main
    bad = tmp_path / "bad.json"
    bad.write_text('{"train": [{"name": "x", "shape": "cube", "color": "red", "dims_cm": [5], "mass_g": 0}]}')
    assert main([str(ROOT / "checkpoints" / "default.pt"), "--objects", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"train/ask.py: error: --objects {bad}: ") and "mass_g" in err, err
    assert main([str(ROOT / "checkpoints" / "default.pt"), "--objects", str(tmp_path / "none.json")]) == 2
    assert f"--objects {tmp_path / 'none.json'}: " in capsys.readouterr().err


def test_a_task_runs_score_says_when_too_few_trials_can_pass():
    """One-sided binomial test at chance 0.5: n of n correct gives p = 0.5 ** n, below 0.05 from n = 5 on; with 2
    trials (p = 0.25 at best) or 4 (0.0625) no score passes, and the line says so instead of "fail"."""
    from train.battery.task_run import verdict
    assert verdict(False, 2, 0.5) == verdict(False, 4, 0.5) == " (too few trials to pass at 0.05)"
    assert verdict(False, 5, 0.5) == " -> fail" and verdict(True, 5, 0.5) == " -> pass"
    assert verdict(False, 3, 1 / 3) == " -> fail"    # (1/3) ** 3 = 0.037: 3 of 3 would pass


@pytest.mark.parametrize("command, words", [("run", "--objects FILE"), ("sweep", "sweep"), ("report", "dir"),
                                            ("ask", "CHECKPOINT")])
def test_each_console_command_answers_help_from_another_directory(tmp_path, monkeypatch, capsys, command, words):
    """pyproject's [project.scripts] entry functions, called as the console command calls them, from a directory
    that is not the repository."""
    try:
        import tomllib
    except ModuleNotFoundError:   # Python 3.10
        import tomli as tomllib

    from aesop_torch import cli
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts[f"aesop-{command}"] == f"aesop_torch.cli:{command}"
    monkeypatch.chdir(tmp_path)
    try:
        code = getattr(cli, command)(["--help"])
    except SystemExit as e:   # argparse's --help
        code = e.code
    out = capsys.readouterr().out
    assert code == 0 and "usage" in out and words in out, out


def test_the_console_command_puts_the_repository_on_the_path_itself(tmp_path):
    """Loaded from its file in a fresh interpreter elsewhere, with nothing of the repository importable, aesop-run's
    entry function finds train/ (the shared environment's install may point at another checkout)."""
    code = ("import importlib.util, sys\n"
            "spec = importlib.util.spec_from_file_location('cli', sys.argv[1])\n"
            "cli = importlib.util.module_from_spec(spec)\n"
            "spec.loader.exec_module(cli)\n"
            "try:\n"
            "    import train\n"
            "    sys.exit('train importable before')\n"
            "except ImportError:\n"
            "    pass\n"
            "cli.run(['--help'])\n")
    r = subprocess.run([sys.executable, "-I", "-c", code, str(ROOT / "aesop_torch" / "cli.py")], cwd=tmp_path,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "usage: train/run.py" in r.stdout, r.stderr


# -- the help and the resume messages (issue 47) ---------------------------------------------------------------------

def test_the_help_lists_every_model_and_every_ablation_from_the_tables(capsys):
    """--help is built from the tables (train/runner/settings.py), so a model or a part added is in it: each with
    its line, and a part that not every model has says which do."""
    from train import run as runner
    from train.common.models import ABLATION_HELP, ABLATIONS, MODEL_HELP, MODELS
    with pytest.raises(SystemExit):
        runner.parse_args(["--help"])
    text = "".join(capsys.readouterr().out.split())   # argparse wraps lines (and breaks at hyphens)
    said = lambda t: "".join(t.split()) in text   # noqa: E731
    parts = {p for m in MODELS for p in ABLATIONS[m]}
    assert set(MODEL_HELP) >= set(MODELS) and set(ABLATION_HELP) >= parts, "a model or a part without its help line"
    for m in MODELS:
        assert said(f"{m}: {MODEL_HELP[m]}"), m
    assert said("fit (contextual only: " + ABLATION_HELP["fit"]) and said("prior (extended only: ")
    assert said("rules (" + ABLATION_HELP["rules"])   # every model has it: no "only"


def test_resume_of_a_contextual_run_takes_its_own_ablation(tmp_path):
    """The run's model comes from its run.json: --ablate fit, a part of the contextual model, agrees with a
    contextual run's (it was refused as 'not a part of the paper model', the default, before run.json was read)."""
    from train import run as runner
    out = tmp_path / "out"
    out.mkdir()
    (out / "run.json").write_text(json.dumps({"objects": {}, "orders": "1", "physics": "cached", "overrides": {
        "model": "contextual", "ablate": ["fit"], "seed": 0}}))
    a = runner.parse_args(["--resume", "--out", str(out), "--ablate", "fit"])
    assert (a.model, a.ablate) == ("contextual", ["fit"])


def test_resume_without_a_checkpoint_says_to_start_again_without_it(tmp_path, capsys):
    from sim.objects import parse_objects
    from train import run as runner
    out = tmp_path / "out"
    out.mkdir()
    objects = parse_objects({"train": [GOOD]})
    (out / "run.json").write_text(json.dumps({"objects": objects.canonical(), "orders": "1", "physics": "cached",
                                              "overrides": {"model": "paper", "ablate": [], "seed": 0}}))
    assert runner.main(["--resume", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no checkpoint at" in err[0] and "start it again without --resume" in err[0], err
    assert runner.main(["--resume", "--out", str(tmp_path / "none")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "start the run without --resume" in err[0], err
