"""benches/battery.py ends as the runner does (train/common/exits.py): Ctrl-C, SIGTERM and SIGHUP give one line and
exit code 128 + the signal, and its worker processes end with it. It had no handling: Ctrl-C gave a traceback, and
SIGTERM ended the main process silently while its workers ran on, printing BrokenPipeError tracebacks. Subprocesses
under a timeout, sent the signal once both workers run."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def children(pid: int) -> list[int]:
    try:
        return [int(k) for t in Path(f"/proc/{pid}/task").iterdir() for k in (t / "children").read_text().split()]
    except FileNotFoundError:
        return []


def running(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False


@pytest.mark.parametrize("sig, group", [(signal.SIGTERM, False), (signal.SIGINT, True)])
def test_a_signal_ends_the_battery_in_one_line_with_its_workers(tmp_path, sig, group):
    p = subprocess.Popen([sys.executable, str(ROOT / "benches" / "battery.py"), "--quick", "--tasks",
                          "sinking_vs_floating", "--trials", "2", "--out", str(tmp_path)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                         preexec_fn=lambda: [signal.signal(s, signal.SIG_DFL)
                                             for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)])
    try:
        t0 = time.monotonic()
        while len(workers := children(p.pid)) < 2:
            assert p.poll() is None and time.monotonic() - t0 < 120, "no two workers"
            time.sleep(0.05)
        time.sleep(0.5)   # at work on their jobs
        (os.killpg if group else os.kill)(p.pid, sig)
        _, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.communicate()
    by = "" if sig == signal.SIGINT else f" by {signal.Signals(sig).name}"
    assert p.returncode == 128 + sig and err.strip() == f"battery: interrupted{by}", (p.returncode, err)
    time.sleep(0.3)
    assert not [w for w in workers if running(w)]
