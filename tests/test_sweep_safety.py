"""train/sweep.py refuses or repairs what would make a sweep's results wrong: damaged, swapped or foreign cell files on
--resume, links inside DIR, a sweep file that is no bounded regular file, SIGTERM and SIGHUP, a cluster it cannot
join; and it records where its rows came from (commit, libraries, times, hosts, the resolved configs)."""

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from train import sweep
from train.common import exits
from train.sweeps import cell as sweep_cell
from train.sweeps import cluster, provenance, store
from train.sweeps import spec as sweep_spec

ROOT = Path(__file__).resolve().parents[1]
CLEAN = "0123abc"   # the commit the tests' cells are written at (clean_commit)

TINY = """
[[conditions]]
name = "paper"
model = "paper"

[[conditions]]
name = "paper -rules"
model = "paper"
ablate = ["rules"]

[[sets]]
name = "fours"
generate = { seeds = [5, 7], train = 4, probe = 3, pairs = false }
orders = 2
checks = [1, 4]
"""


@pytest.fixture(autouse=True)
def clean_commit(monkeypatch):
    """This checkout taken for a clean commit, CLEAN: a developer's uncommitted changes would make every --resume
    here refuse (that refusal has its own tests, which give the commits)."""
    monkeypatch.setattr(provenance, "commit", lambda: CLEAN)


def _write(tmp_path: Path, text: str, name: str = "sweep.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def _sorted(table):
    return table.sort_by([("cell", "ascending"), ("order", "ascending"), ("episode", "ascending")])


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A finished sweep of TINY's 4 cells, written here without Ray (the rows are run_cell's either way): its sweep
    file, its cells (load order) and its DIR, for each test to copy."""
    base = tmp_path_factory.mktemp("finished")
    path = _write(base, TINY)
    spec, cells = sweep_spec.load_sweep(path)
    out = base / "out"
    (out / "cells").mkdir(parents=True)
    store.write_record(out, {"format": sweep_spec.FORMAT, "sweep_file": str(path), "spec": spec,
                              "cells": [c["id"] for c in cells], "runs": []})
    for c in cells:
        store.write_cell(out, c["id"], sweep_cell.run_cell(c["spec"], c["objects"], commit=CLEAN))
    return path, cells, out


def _copy(finished, tmp_path: Path) -> Path:
    out = tmp_path / "out"
    shutil.copytree(finished[2], out)
    return out


# -- 1. --resume checks each file -----------------------------------------------------------------------------------

def _damage(kind: str, cells_dir: Path, ids: list[str]) -> str:
    """Damage the file of cell ids[1] (or add a foreign one) as `kind` says; returns the words its line must hold."""
    a, b = cells_dir / f"{ids[0]}.parquet", cells_dir / f"{ids[1]}.parquet"
    data = b.read_bytes()
    if kind == "truncated":
        b.write_bytes(data[: len(data) // 2])
        return "not a readable Parquet file (Parquet magic bytes not found in footer"
    if kind == "zero bytes":
        b.write_bytes(b"")
        return "empty (0 bytes)"
    if kind == "swapped":   # cell A's file renamed as cell B's
        shutil.copyfile(a, b)
        return f"holds the rows of cell {ids[0]}, not {ids[1]} (renamed?)"
    if kind == "corrupt":   # the last byte of the observed_cm3 column's data page flipped: its CRC no longer matches
        col = pq.read_metadata(b).row_group(0).column(sweep_cell.schema().names.index("observed_cm3"))
        end = (col.dictionary_page_offset if col.has_dictionary_page else col.data_page_offset) + \
            col.total_compressed_size
        flipped = bytearray(data)
        flipped[end - 1] ^= 0xFF
        b.write_bytes(bytes(flipped))
        return "not a readable Parquet file (could not verify page integrity, CRC checksum verification failed"
    if kind == "rows of another cell":   # the cell column says B, the rows are A's (another condition)
        t = pq.read_table(a)
        t = t.set_column(0, "cell", pa.array([ids[1]] * t.num_rows, pa.string()))
        b.write_bytes(store.encode_cell(t.replace_schema_metadata(None)))
        return "its rows' condition is paper -rules, not this cell's paper"
    raise AssertionError(kind)


@pytest.mark.parametrize("kind", ["truncated", "zero bytes", "swapped", "corrupt", "rows of another cell"])
def test_a_damaged_cell_file_is_not_counted_finished(finished, tmp_path, kind):
    path, cells, _ = finished
    out = _copy(finished, tmp_path)
    # ids[0] of "paper -rules", ids[1] of "paper", same set and seed: a swap keeps the set and seed columns right
    pr = next(c for c in cells if c["spec"]["condition"]["name"] == "paper -rules")
    p = next(c for c in cells if c["spec"]["condition"]["name"] == "paper" and c["spec"]["seed"] == pr["spec"]["seed"])
    words = _damage(kind, out / "cells", [pr["id"], p["id"]])
    done, foreign, bad = store.survey(out, cells)
    assert done == {c["id"] for c in cells} - {p["id"]} and foreign == []
    assert [(q.name, why) for q, why in bad] == [(f"{p['id']}.parquet", bad[0][1])] and words in bad[0][1], bad


def test_a_foreign_file_is_reported_and_never_counted(finished, tmp_path):
    _, cells, _ = finished
    out = _copy(finished, tmp_path)
    shutil.copyfile(out / "cells" / f"{cells[0]['id']}.parquet", out / "cells" / "0123456789abcdef.parquet")
    (out / "cells" / "notes.txt").write_text("mine")
    (out / "cells" / f".{cells[0]['id']}.parquet.x1.tmp").write_bytes(b"half")   # a killed write's temporary file
    done, foreign, bad = store.survey(out, cells)
    assert done == {c["id"] for c in cells} and bad == []
    assert foreign == ["0123456789abcdef.parquet", "notes.txt"]


def test_resume_reruns_damaged_cells_and_records_where_the_rows_came_from(finished, tmp_path, local_ray, capsys):
    """Swapped, truncated and empty files run again (kept aside as *.rejected), a foreign file is named and left
    alone; the table is then the cells' own rows, and sweep.json and each file say how and where they were made."""
    path, cells, _ = finished
    out = _copy(finished, tmp_path)
    want = _sorted(store.read_cells(out))
    d = out / "cells"
    ids = [c["id"] for c in cells]
    shutil.copyfile(d / f"{ids[0]}.parquet", d / f"{ids[1]}.parquet")                    # swapped
    (d / f"{ids[2]}.parquet").write_bytes((d / f"{ids[2]}.parquet").read_bytes()[:3000])  # truncated
    (d / f"{ids[3]}.parquet").write_bytes(b"")                                           # zero bytes
    shutil.copyfile(d / f"{ids[0]}.parquet", d / "feedfacefeedface.parquet")              # foreign
    assert sweep.main([str(path), "--out", str(out), "--resume"]) == 0
    captured = capsys.readouterr()
    err = [x for x in captured.err.splitlines() if not x.startswith("cells: ")]   # progress lines aside
    assert err == [
        f"train/sweep.py: {d / 'feedfacefeedface.parquet'} is no cell of this sweep: not counted (move it out of {d})",
        *sorted(f"train/sweep.py: {d / f'{i}.parquet'}: {why}: its cell runs again (the file is kept as "
                f"{i}.parquet.rejected)" for i, why in (
                    (ids[1], f"holds the rows of cell {ids[0]}, not {ids[1]} (renamed?)"),
                    (ids[2], "not a readable Parquet file (Parquet magic bytes not found in footer. Either the file "
                             "is corrupted or this is not a parquet file.)"),
                    (ids[3], "empty (0 bytes)")))], err
    assert "1 on disk, 3 to run" in captured.out
    assert sorted(p.name for p in d.iterdir()) == sorted(
        [f"{i}.parquet" for i in ids] + [f"{i}.parquet.rejected" for i in ids[1:]] + ["feedfacefeedface.parquet"])
    assert _sorted(store.read_cells(out, ids)).equals(want)
    assert store.survey(out, cells)[0] == set(ids)

    # provenance: this run's entry in sweep.json, the cells it ran with their host and wall time
    record = json.loads((out / "sweep.json").read_text())
    assert record["cells"] == ids and len(record["runs"]) == 1
    run = record["runs"][0]
    assert run["resumed"] is True and run["ended_by"] == "finished" and run["cells_run"] == 3
    assert run["started"] <= run["ended"] and run["ended"].endswith("Z") and len(run["started"]) == 20
    assert set(run["versions"]) == {"python", "torch", "numpy", "pybullet", "pyarrow", "ray"}
    assert run["versions"]["pyarrow"] == pa.__version__ and run["commit"] == provenance.commit()
    assert set(run["cells"]) == set(ids[1:])
    host = socket.gethostname()
    assert all(v["host"] == host and v["wall_s"] > 0 for v in run["cells"].values())
    # ... and in each file it wrote, with the config it ran: its hash in every row, the config in configs.json
    configs = json.loads((out / "configs.json").read_text())
    for i in ids[1:]:
        info = store.cell_info(d / f"{i}.parquet")
        assert info["cell"] == i and info["commit"] == run["commit"] and info["host"] == host
        assert info["wall_s"] == run["cells"][i]["wall_s"] and info["versions"] == run["versions"]
        rows = pq.read_table(d / f"{i}.parquet", columns=["config"]).column("config").unique().to_pylist()
        assert rows == [info["config"]] and configs[info["config"]] == info["config_record"]
        assert sweep_cell.config_hash(configs[info["config"]]) == info["config"]
    assert store.cell_info(d / f"{ids[0]}.parquet") == {}   # written by the fixture, without provenance


def test_the_config_column_names_the_resolved_configs(finished, tmp_path):
    """One config per condition and set size (the seed is the rows' own column); an override makes another."""
    _, cells, _ = finished
    by_cond = {}
    for c in cells:
        by_cond.setdefault(c["spec"]["condition"]["name"], set()).add(sweep_cell.config_hash(sweep_cell.config_record(c["spec"])))
    assert len(by_cond["paper"]) == len(by_cond["paper -rules"]) == 1 and by_cond["paper"] != by_cond["paper -rules"]
    rec = sweep_cell.config_record(cells[0]["spec"])
    assert "seed" not in rec["agent"] and rec["agent"]["memory"]["max_episodes"] == 4
    assert rec["world"] == {"name": "closed_form", "sensor": rec["world"]["sensor"], "reachable_above_cm3": 200.0}
    assert rec["world"]["sensor"]["mass_sd_g"] > 0
    pytest.importorskip("train.common.config")
    _, other = sweep_spec.load_sweep(_write(tmp_path, TINY.replace('ablate = ["rules"]',
                                                                'overrides = { "rules.uncertain_decay" = 1.0 }')))
    rec2 = sweep_cell.config_record(next(c for c in other if c["spec"]["condition"]["name"] == "paper -rules")["spec"])
    assert rec2["agent"]["rules"]["uncertain_decay"] == 1.0 and sweep_cell.config_hash(rec2) not in by_cond["paper"]


# -- 2. links inside DIR --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("where", ["cells", "sweep.json", "a cell file"])
def test_resume_refuses_a_link_inside_dir_and_writes_nothing_through_it(finished, tmp_path, capsys, where):
    path, cells, _ = finished
    out = _copy(finished, tmp_path)
    elsewhere = tmp_path / "elsewhere"
    if where == "cells":
        shutil.move(out / "cells", elsewhere)
        os.symlink(elsewhere, out / "cells")
        (elsewhere / f"{cells[0]['id']}.parquet").unlink()   # a cell to run: it would be written into the target
        link = out / "cells"
    elif where == "sweep.json":
        elsewhere.mkdir()
        shutil.move(out / "sweep.json", elsewhere / "sweep.json")
        os.symlink(elsewhere / "sweep.json", out / "sweep.json")
        link = out / "sweep.json"
    else:
        elsewhere.mkdir()
        link = out / "cells" / f"{cells[0]['id']}.parquet"
        shutil.move(link, elsewhere / link.name)
        os.symlink(elsewhere / link.name, link)
    before = sorted((p.name, p.stat().st_mtime_ns) for p in elsewhere.iterdir())
    assert sweep.main([str(path), "--out", str(out), "--resume"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.splitlines() == [
        f"train/sweep.py: error: --resume: {link} is a symbolic link; the sweep writes only inside --out {out}: "
        f"remove it"]
    assert sorted((p.name, p.stat().st_mtime_ns) for p in elsewhere.iterdir()) == before


def test_an_out_that_is_a_link_to_nothing_is_refused(finished, tmp_path, capsys):
    os.symlink(tmp_path / "nowhere", tmp_path / "out")
    assert sweep.main([str(finished[0]), "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"train/sweep.py: error: --out {tmp_path / 'out'} is a symbolic link to nothing ({tmp_path / 'nowhere'})"]
    assert not (tmp_path / "nowhere").exists()


# -- 3. SIGTERM and SIGHUP ------------------------------------------------------------------------------------------

@pytest.mark.timeout(180)
def test_sigterm_ends_a_sweep_as_ctrl_c(tmp_path):
    """SIGTERM to the sweep's process (kill, timeout), after ray.init put its own handler (sys.exit(15)) in place:
    one line, exit code 143, every finished cell on disk and the run recorded as ended so."""
    path = _write(tmp_path, TINY.replace("seeds = [5, 7]", "seeds = [5, 45]"))
    out = tmp_path / "out"
    p = subprocess.Popen([sys.executable, "train/sweep.py", str(path), "--out", str(out), "--workers", "2"], cwd=ROOT,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while not list((out / "cells").glob("*.parquet")) and time.monotonic() < deadline and p.poll() is None:
            time.sleep(0.05)
        os.kill(p.pid, signal.SIGTERM)
        stdout, stderr = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    done = list((out / "cells").glob("*.parquet"))
    lines = [x for x in stderr.strip().splitlines() if not x.startswith("cells: ")]   # progress lines aside
    assert p.returncode == 143 and lines == [
        f"train/sweep.py: interrupted by SIGTERM: {len(done)} of 80 cell(s) on disk in {out / 'cells'} "
        f"(--resume runs the rest)"], stderr
    assert 1 <= len(done) < 80 and store.read_cells(out).num_rows == len(done) * 2 * 4
    run = json.loads((out / "sweep.json").read_text())["runs"][-1]
    assert run["ended_by"] == "interrupted by SIGTERM" and run["cells_run"] == len(done)
    assert _survivors(p.pid) == []   # Ray's processes ended with the sweep


def _survivors(session: int, wait: float = 3.0) -> list[str]:
    """The live processes of a session (the sweep started with start_new_session: its pid), after up to `wait`
    seconds for them to end; each killed here, so that a failing test leaves none."""
    deadline = time.monotonic() + wait
    while True:
        left = {}
        for p in Path("/proc").iterdir():
            try:
                fields = (p / "stat").read_text().rsplit(")", 1)[1].split() if p.name.isdigit() else None
                if fields and int(fields[3]) == session and fields[0] not in "ZX":
                    left[int(p.name)] = (p / "cmdline").read_bytes().replace(b"\0", b" ").decode()[:60].strip()
            except (OSError, IndexError):
                continue
        if not left or time.monotonic() > deadline:
            break
        time.sleep(0.1)
    for pid in left:
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)
    return sorted(left.values())


ORPHAN = """import os, signal, sys, time
pid = os.fork()
if pid == 0:   # the grandchild: deaf to SIGTERM, as Ray's agents are, and orphaned when its parent exits
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    time.sleep(60)
    os._exit(0)
open(sys.argv[1], "w").write(str(pid))
"""


def test_an_interrupted_ray_start_leaves_no_process_behind(tmp_path, monkeypatch, capsys):
    """Ctrl-C while Ray starts, its stand-in here: a process that starts one deaf to SIGTERM and exits, orphaning it
    (as raylet's end orphans ray::DashboardAgent and ray::RuntimeEnvAgent). The sweep ends in one line and the orphan
    with it."""
    import ray

    from train.sweeps import driver
    pid_file = tmp_path / "orphan.pid"

    def starting(address, workers):
        subprocess.run([sys.executable, "-c", ORPHAN, str(pid_file)], timeout=30, check=True)
        raise KeyboardInterrupt

    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    monkeypatch.setattr(driver, "start_ray", starting)
    path = _write(tmp_path, TINY)
    try:
        assert sweep.main([str(path), "--out", str(tmp_path / "out")]) == 130
        assert capsys.readouterr().err.splitlines() == ["train/sweep.py: interrupted before the sweep started"]
        orphan = Path(f"/proc/{pid_file.read_text()}/stat")
        assert not orphan.exists() or orphan.read_text().rsplit(")", 1)[1].split()[0] in "ZX"
    finally:
        with contextlib.suppress(OSError, ValueError):
            os.kill(int(pid_file.read_text()), signal.SIGKILL)


@pytest.mark.timeout(180)
def test_a_signal_while_ray_starts_leaves_no_process_behind(tmp_path):
    """The real thing: SIGTERM once Ray's agents run but (most times) before ray.init has returned, the moment that
    left ray::DashboardAgent and ray::RuntimeEnvAgent running (7 of 7): one line, exit code 143, no survivor."""
    path = _write(tmp_path, TINY)
    p = subprocess.Popen([sys.executable, "train/sweep.py", str(path), "--out", str(tmp_path / "out"), "--workers",
                          "1"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and p.poll() is None and not any(
                "ray::RuntimeEnvAgent" in c for c in _session_commands(p.pid)):
            time.sleep(0.02)
        os.kill(p.pid, signal.SIGTERM)
        _, stderr = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    lines = [x for x in stderr.strip().splitlines() if not x.startswith("cells: ")]
    assert p.returncode == 143 and len(lines) == 1 and "interrupted by SIGTERM" in lines[0], stderr
    assert _survivors(p.pid) == []


def _session_commands(session: int) -> list[str]:
    found = []
    for p in Path("/proc").iterdir():
        try:
            if p.name.isdigit() and int((p / "stat").read_text().rsplit(")", 1)[1].split()[3]) == session:
                found.append((p / "cmdline").read_bytes().decode(errors="replace"))
        except (OSError, IndexError):
            continue
    return found


def test_sighup_ends_a_sweep_as_ctrl_c(finished, tmp_path, local_ray, capsys):
    """SIGHUP (a closed terminal) after the first cell: exit code 129, one line, the cell on disk."""
    path = _write(tmp_path, TINY)
    out = tmp_path / "out"
    # a SIGHUP ignored stays ignored (nohup: the sweep goes on, by design): the test's own, under nohup too, is not
    previous = signal.signal(signal.SIGHUP, signal.SIG_DFL)
    try:
        code = sweep.main([str(path), "--out", str(out)], on_cell=lambda c: os.kill(os.getpid(), signal.SIGHUP))
    finally:
        signal.signal(signal.SIGHUP, previous)
    done = list((out / "cells").glob("*.parquet"))
    assert code == 129 and len(done) == 1
    assert [x for x in capsys.readouterr().err.splitlines() if not x.startswith("cells: ")] == [
        f"train/sweep.py: interrupted by SIGHUP: 1 of 4 cell(s) on disk in {out / 'cells'} (--resume runs the rest)"]
    assert json.loads((out / "sweep.json").read_text())["runs"][-1]["ended_by"] == "interrupted by SIGHUP"
    assert signal.getsignal(signal.SIGHUP) is not exits._ended   # the handlers before main() are back


# -- 4. the sweep file ----------------------------------------------------------------------------------------------

def _refused(args, timeout=60):
    r = subprocess.run([sys.executable, "train/sweep.py", *args], cwd=ROOT, capture_output=True, text=True,
                       timeout=timeout, stdin=subprocess.DEVNULL)
    return r.returncode, r.stdout, r.stderr.splitlines()


@pytest.mark.timeout(60)
def test_a_sweep_file_that_is_a_device_or_a_fifo_is_refused_at_once(tmp_path):
    fifo = tmp_path / "sweep.toml"
    os.mkfifo(fifo)
    for target, kind in (("/dev/zero", "a device"), (str(fifo), "a FIFO (named pipe)"),
                         (str(tmp_path), "a directory")):
        t0 = time.monotonic()
        code, out, err = _refused([target, "--out", str(tmp_path / "out")], timeout=30)
        assert code == 2 and out == "" and len(err) == 1, err
        assert err[0] in (f"train/sweep.py: error: {target}: is {kind}, not a sweep file (a regular file)",
                          f"train/sweep.py: error: {target}: cannot read it: Is a directory"), err
        assert time.monotonic() - t0 < 20 and not (tmp_path / "out").exists()


def test_a_sweep_file_larger_than_the_limit_is_not_read(tmp_path, capsys):
    path = _write(tmp_path, "# " + "x" * sweep_spec.MAX_SWEEP_BYTES + "\n" + TINY)
    assert sweep.main([str(path), "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"train/sweep.py: error: {path}: larger than 1,000,000 bytes, too large for a sweep file"]


DEEP = ["a = " + "[" * 5000 + "]" * 5000, "a = " + "{b = " * 5000 + "1" + "}" * 5000, ".".join(["a"] * 5000) + " = 1",
        TINY.replace("checks = [1, 4]", "checks = " + "[" * 17 + "1" + "]" * 17)]


@pytest.mark.parametrize("text", DEEP)
def test_a_sweep_file_nested_5000_deep_is_refused_in_one_line(tmp_path, capsys, text):
    path = _write(tmp_path, text)
    assert sweep.main([str(path), "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"train/sweep.py: error: {path}: nests tables or lists more than 16 levels deep"]


@pytest.mark.parametrize("text, words", [
    (TINY.replace('model = "paper"\n', 'model = "paper"\nname = "again"\n', 1),
     "malformed TOML: the key name is given twice (line 5; a key may be set once per table)"),
    (TINY.replace("orders = 2", "orders = 2\norders = 3"),
     "malformed TOML: the key orders is given twice (line 15; a key may be set once per table)"),
    ("description = \"x\"\n" + TINY.replace("train = 4,", "train = 4, train = 5,"),
     "malformed TOML: Duplicate inline table key 'train' (at line 14, column"),
    ("[t]\na = 1\n[t]\nb = 2\n", "malformed TOML: Cannot declare ('t',) twice (at line 3, column 3)"),
])
def test_a_key_given_twice_is_refused_in_one_line_naming_it(tmp_path, capsys, text, words):
    path = _write(tmp_path, text)
    assert sweep.main([str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"train/sweep.py: error: {path}: {words}"), err


# -- 7. joining a cluster -------------------------------------------------------------------------------------------

@pytest.mark.timeout(90)
def test_an_address_nothing_listens_on_is_refused_in_one_line(finished, tmp_path):
    with socket.socket() as s:   # a port free a moment ago; nothing listens on it
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    code, out, err = _refused([str(finished[0]), "--out", str(tmp_path / "out"), "--address", f"127.0.0.1:{port}"])
    assert code == 2 and len(err) == 1 and "Traceback" not in err[0], err
    assert err[0] == (f"train/sweep.py: error: cannot join Ray at 127.0.0.1:{port}: it does not answer (Connection "
                      f"refused); check the address (`ray start --head` prints it, `ray status` on its node)")
    assert not (tmp_path / "out").exists()


@pytest.fixture
def refusing_gcs():
    """A gRPC server that refuses every call as a Ray cluster with token authentication refuses a driver without
    the token (status UNAUTHENTICATED, Ray's own message); its port. On every interface: Ray dials the node's address
    for 127.0.0.1."""
    from concurrent import futures

    import grpc

    class Refuse(grpc.GenericRpcHandler):
        def service(self, details):
            def deny(request, context):
                context.abort(grpc.StatusCode.UNAUTHENTICATED, "Invalid or missing authentication token")
            return grpc.unary_unary_rpc_method_handler(deny)

    server = grpc.server(futures.ThreadPoolExecutor(max_workers=2))
    server.add_generic_rpc_handlers((Refuse(),))
    port = server.add_insecure_port("0.0.0.0:0")
    server.start()
    yield port
    server.stop(0)


@pytest.mark.timeout(90)
def test_a_cluster_that_refuses_the_sweep_without_a_token_is_named_in_one_line(finished, tmp_path, refusing_gcs):
    """What Ray prints for it (a screenful of 'Unauthenticated: RPC error' lines, then 'Failed to connect to Ray
    cluster') becomes one line naming RAY_AUTH_MODE=token; Ray's retries cut to 2 here to keep the test short."""
    env = {**os.environ, "RAY_NUM_REDIS_GET_RETRIES": "2"}
    env.pop("RAY_AUTH_MODE", None)
    r = subprocess.run([sys.executable, "train/sweep.py", str(finished[0]), "--out", str(tmp_path / "out"),
                        "--address", f"127.0.0.1:{refusing_gcs}"], cwd=ROOT, capture_output=True, text=True,
                       timeout=80, env=env, stdin=subprocess.DEVNULL)
    assert r.returncode == 2 and r.stderr.splitlines() == [
        f"train/sweep.py: error: cannot join Ray at 127.0.0.1:{refusing_gcs}: the cluster requires token "
        f"authentication: set RAY_AUTH_MODE=token (and its token: RAY_AUTH_TOKEN or ~/.ray/auth_token) and run the "
        f"sweep again"], r.stderr
    assert not (tmp_path / "out").exists()


def test_a_refused_authentication_is_named_with_its_fix():
    import ray
    auth = ray.exceptions.AuthenticationError("Authentication failed: UNAUTHENTICATED")
    assert cluster._join_failure("10.0.0.5:6379", auth, "") == (
        "cannot join Ray at 10.0.0.5:6379: the cluster requires token authentication: set RAY_AUTH_MODE=token (and its "
        "token: RAY_AUTH_TOKEN or ~/.ray/auth_token) and run the sweep again")
    # the gRPC lines Ray printed while it retried say so, when its exception does not
    said = "E1206 rpc_client.h:212] Failed to connect to GCS: UNAUTHENTICATED: Invalid or missing token\n" * 20
    line = cluster._join_failure("10.0.0.5:6379", ConnectionError("Could not connect to the GCS"), said)
    assert "\n" not in line and "RAY_AUTH_MODE=token" in line and "10.0.0.5:6379" in line
    other = cluster._join_failure("10.0.0.5:6379", RuntimeError("Version mismatch: 2.9 and 2.60\nmore"), "")
    assert other.startswith("cannot join Ray at 10.0.0.5:6379: Version mismatch: 2.9 and 2.60; ") and "\n" not in other
    assert "RAY_AUTH_MODE=token" in other


# -- 8. the docs' examples ------------------------------------------------------------------------------------------

def test_the_docs_python_example_runs_on_a_tiny_sweeps_output(tmp_path, local_ray, capsys):
    """docs/sweeps.md's "Reading the rows" block, run as written (pyarrow only) on examples/tiny.toml's sweep."""
    out = tmp_path / "sweep-tiny"
    assert sweep.main([str(ROOT / "examples" / "tiny.toml"), "--out", str(out)]) == 0
    capsys.readouterr()
    text = (ROOT / "docs" / "sweeps.md").read_text()
    blocks = [b.split("```")[0] for b in text.split("```python\n")[1:]]
    assert len(blocks) == 1 and 'DIR = "runs/sweep-tiny"\n' in blocks[0] and "pandas" not in blocks[0]
    exec(compile(blocks[0].replace('DIR = "runs/sweep-tiny"', f"DIR = {str(out)!r}"), "docs/sweeps.md", "exec"), {})
    lines = capsys.readouterr().out.splitlines()
    rows = store.read_cells(out)
    final = [r for r in rows.to_pylist() if r["episode"] == r["n_train"]]
    assert lines[:len(final)] == [f"{r['condition']} {r['set']} {r['seed']} {r['order']} {r['knowledge']}"
                                  for r in final]
    at4 = [r["probe_rel_error"] for r in final if r["condition"] == "paper"]
    assert f"paper: after 4 episodes, 4 runs, mean error {100 * sum(at4) / 4:.1f} %" in lines
    assert lines[-1].startswith(json.loads((out / "sweep.json").read_text())["runs"][0]["started"] + " ")
    assert lines[-1].endswith(" finished " + provenance.commit() + " " + provenance.versions()["torch"])


@pytest.mark.parametrize("content, words", [
    ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
    ("{}", "KeyError: 'spec'"),
    ("x", "JSONDecodeError: Expecting value: line 1 column 1 (char 0)"),
])
def test_a_damaged_sweep_record_is_refused_on_resume_in_one_line(finished, tmp_path, capsys, content, words):
    out = _copy(finished, tmp_path)
    (out / "sweep.json").write_text(content)
    assert sweep.main([str(finished[0]), "--out", str(out), "--resume"]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"train/sweep.py: error: --resume: cannot read {out / 'sweep.json'}: {words}"]


# -- 9. code that mixes, values out of range, a missing pyarrow -----------------------------------------------------

def _one_missing(finished, tmp_path) -> tuple[Path, list]:
    """A copy of the finished sweep with its first cell's file removed (one cell to run on --resume)."""
    out = _copy(finished, tmp_path)
    (out / "cells" / f"{finished[1][0]['id']}.parquet").unlink()
    return out, finished[1]


@pytest.mark.parametrize("this, words", [
    ("fedcba9", "the 3 cell(s) on disk were written at 0123abc (3 cells), not at this checkout's fedcba9; check "
                "that commit out, sweep into another --out, or --allow-mixed-commits to mix them (the report says so)"),
    ("0123abc-dirty", "this checkout has uncommitted changes (0123abc-dirty), so its cells would not be the same "
                      "code as the 3 on disk (written at 0123abc (3 cells)); commit, or --allow-mixed-commits to mix "
                      "them (the report says so)"),
    ("unknown", "this checkout's commit is unknown (not a git checkout?), so its cells would not be the same code as "
                "the 3 on disk (written at 0123abc (3 cells)); commit, or --allow-mixed-commits to mix them (the "
                "report says so)"),
])
def test_resume_refuses_cells_of_other_code_in_one_line(finished, tmp_path, monkeypatch, capsys, this, words):
    out, _ = _one_missing(finished, tmp_path)
    before = sorted((p.name, p.stat().st_mtime_ns) for p in out.rglob("*"))
    monkeypatch.setattr(provenance, "commit", lambda: this)
    assert sweep.main([str(finished[0]), "--out", str(out), "--resume"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.splitlines() == [f"train/sweep.py: error: --resume: {words}"]
    assert sorted((p.name, p.stat().st_mtime_ns) for p in out.rglob("*")) == before   # nothing written


def test_cells_written_from_a_dirty_tree_are_refused_even_at_the_same_string(finished, tmp_path, monkeypatch, capsys):
    """Two dirty trees at one commit need not hold the same code: the commit does not name it."""
    out, cells = _one_missing(finished, tmp_path)
    for c in cells[1:]:
        store.write_cell(out, c["id"], sweep_cell.run_cell(c["spec"], c["objects"], commit="0123abc-dirty"))
    monkeypatch.setattr(provenance, "commit", lambda: "0123abc-dirty")
    assert sweep.main([str(finished[0]), "--out", str(out), "--resume"]) == 2
    assert "this checkout has uncommitted changes (0123abc-dirty)" in capsys.readouterr().err


def test_allow_mixed_commits_runs_the_rest_and_the_report_names_every_commit(finished, tmp_path, monkeypatch,
                                                                             local_ray, capsys):
    out, cells = _one_missing(finished, tmp_path)
    monkeypatch.setattr(provenance, "commit", lambda: "fedcba9")
    assert sweep.main([str(finished[0]), "--out", str(out), "--resume", "--allow-mixed-commits"]) == 0
    err = [x for x in capsys.readouterr().err.splitlines() if not x.startswith("cells: ")]
    assert err == ["train/sweep.py: --allow-mixed-commits: the cells on disk were written at 0123abc (3), the cells "
                   "run now at fedcba9; the report says so"]
    rows = store.read_cells(out)
    by_cell = dict(zip(rows.column("cell").to_pylist(), rows.column("commit").to_pylist()))
    assert by_cell == {c["id"]: "fedcba9" if c is cells[0] else "0123abc" for c in cells}   # every row its commit
    run = json.loads((out / "sweep.json").read_text())["runs"][-1]
    assert run["allow_mixed_commits"] is True and run["commit"] == "fedcba9"
    from train import report as report_cli
    assert report_cli.main([str(out)]) == 0
    mixed = ["commits: MIXED CODE, 2 commits: 0123abc (3 cells), fedcba9 (1 cell)",
             "the cells were not all computed by the same code (--resume --allow-mixed-commits): compare conditions "
             "only within one commit's cells (the rows' commit column)"]
    assert (out / "report.csv").read_text().splitlines()[:2] == [f"# {line}" for line in mixed]
    assert (out / "report.md").read_text().splitlines()[2:4] == [f"- {line}" for line in mixed]
    # without --resume the flag means nothing: refused
    assert sweep.main([str(finished[0]), "--out", str(tmp_path / "new"), "--allow-mixed-commits"]) == 2
    assert capsys.readouterr().err.splitlines() == [
        "train/sweep.py: error: --allow-mixed-commits goes with --resume (a new sweep writes all its cells at one "
        "commit)"]


@pytest.mark.parametrize("column, value, words", [
    ("probe_rel_error", float("nan"), "its column probe_rel_error holds nan at row 3, not a relative error (0 to "
                                      "1e+09, or none)"),
    ("probe_rel_error", -2699268.624, "its column probe_rel_error holds -2699268.624 at row 3, not a relative error"),
    ("observed_cm3", 1e12, "its column observed_cm3 holds 1000000000000.0 at row 3, not a rise a jar holds (at most "
                           "29,063 cm^3)"),
    ("predicted_cm3", float("inf"), "its column predicted_cm3 holds inf at row 3, not a prediction"),
    ("knowledge", "UUXU", "its column knowledge holds 'UUXU' at row 3, not letters of ULDI"),
    ("episode", 7, "its column episode holds 7 at row 3, not an episode of the cell (1 to n_train)"),
    ("probe_errors", [0.1, float("nan"), 0.2], "its column probe_errors holds nan at row 3, not a relative error"),
])
def test_a_cell_rewritten_out_of_range_with_a_valid_checksum_is_refused(finished, tmp_path, capsys, column, value,
                                                                        words):
    """A cell file rewritten with NaN or an absurd value (its pages' checksums valid: encode_cell wrote it) is named
    with its column, row and value: --resume runs the cell again, the report refuses it in one line."""
    out = _copy(finished, tmp_path)
    cells = finished[1]
    target = out / "cells" / f"{cells[1]['id']}.parquet"
    t = pq.read_table(target).replace_schema_metadata(None)
    values = t.column(column).to_pylist()
    values[3] = value
    t = t.set_column(t.schema.get_field_index(column), column, pa.array(values, t.schema.field(column).type))
    target.write_bytes(store.encode_cell(t))
    done, _, bad = store.survey(out, cells)
    assert done == {c["id"] for c in cells} - {cells[1]["id"]}
    assert [(p, why) for p, why in bad] == [(target, bad[0][1])] and bad[0][1].startswith(words), bad
    from train import report as report_cli
    assert report_cli.main([str(out)]) == 2
    line, = capsys.readouterr().err.splitlines()
    assert line.startswith(f"train.report: error: {target}: {words}") and line.endswith("runs its cell again")
    assert not (out / "report.md").exists()


def test_a_missing_pyarrow_is_named_as_such(finished, tmp_path, monkeypatch, capsys):
    """Not 'not a readable Parquet file ... runs its cell again' for every good file (and each set aside)."""
    out = _copy(finished, tmp_path)
    before = sorted(p.name for p in (out / "cells").iterdir())
    for name in [m for m in sys.modules if m == "pyarrow" or m.startswith("pyarrow.")]:
        monkeypatch.setitem(sys.modules, name, None)
    assert sweep.main([str(finished[0]), "--out", str(out), "--resume"]) == 2
    from train import report as report_cli
    assert report_cli.main([str(out)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and all("pyarrow is not installed" in x and "Parquet" in x for x in err), err
    assert err[0].startswith("train/sweep.py: error: ") and err[1].startswith("train.report: error: ")
    assert sorted(p.name for p in (out / "cells").iterdir()) == before   # no file set aside
