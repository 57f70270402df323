"""Tensorboard for a run: one run directory per presentation order, tags as in CONTRACTS.md.

Scalars `certainty/<property>`, `prediction/abs_error_cm3` (|prediction - Archimedes| for the dropped object, once a
prediction can be made), `prediction/probe_rel_error`, `rules/<property>/<E|G|U|S>` (1 when that rule fired that
episode, else 0); text `episodes` (one line per episode); hparams once per run, in the run's own directory.
Goal trials (train/learning/goal_trials.py), step = trial (1-based): `trials/drops`, `trials/excess_drops` (drops beyond the
planner's fewest) and text `trials` (one line per trial).

A write that fails in tensorboard's writer thread (a full disk) is raised again by the writer in the caller's next
write, flush or close, as an OSError naming the log's directory: the runner's one line. The thread's own traceback is
not printed (`_quiet_writer_threads`).
"""

from __future__ import annotations

import contextlib
import threading
from pathlib import Path

from tensorboard.summary.writer import record_writer
from tensorboard.summary.writer.event_file_writer import _AsyncWriterThread
from torch.utils.tensorboard import SummaryWriter
from torch.utils.tensorboard.summary import hparams
from torch.utils.tensorboard.summary import image as image_summary

from aesop_torch.encoders import object_properties
from aesop_torch.rules import RULE_NAMES


def episode_line(t: int, rec: dict) -> str:
    exp = "-" if rec["predicted_cm3"] is None else f"{rec['predicted_cm3']:.1f}"
    rules = " ".join(f"{p}:{rec['rules'][p]}" for p in object_properties(rec["rules"]))
    line = (f"episode {t + 1}: {rec['object']} expected={exp} observed={rec['observed_cm3']:.1f} "
            f"archimedes={rec['archimedes_cm3']:.1f} rules[{rules}] encoded={rec['encoded']}")
    seen, true = rec.get("perceived"), rec.get("true") or {}
    if seen:  # perceived, the true value in brackets (records from before perception was logged have neither)
        def pair(key, fmt):
            show = (lambda v: "x".join(fmt.format(x) for x in v)) if isinstance(seen[key], list) else fmt.format
            return f" {key}={show(seen[key])}" + (f" ({show(true[key])})" if key in true else "")
        line += (" perceived: rgb=" + "/".join(f"{x:.2f}" for x in seen["rgb"]) + pair("extent_cm", "{:.2f}")
                 + pair("fill", "{:.3f}") + pair("mass_g", "{:.1f}"))
    return line


def trial_line(i: int, rec: dict) -> str:
    exp = lambda v: "-" if v is None else f"{v:.0f}"
    chose = " > ".join(f"{n} (expected {exp(e)}, observed {o:.0f})"
                       for n, e, o in zip(rec["chosen"], rec["expected_cm3"], rec["observed_cm3"]))
    return (f"trial {i + 1}: {chose}; {rec['drops']} drop(s), fewest {rec['fewest_drops']}, random "
            f"{rec['random_drops_mean']:.2f}, goal {'reached' if rec['goal_reached'] else 'not reached'}")


def _quiet_writer_threads(args, _previous=threading.excepthook) -> None:
    """threading.excepthook: silent for tensorboard's writer thread, whose exception its writer raises again in the
    writing thread (the runner reports it in one line); every other thread's as before."""
    if isinstance(args.thread, _AsyncWriterThread) and issubclass(args.exc_type, Exception):
        return
    _previous(args)


if getattr(threading.excepthook, "__name__", "") != _quiet_writer_threads.__name__:
    threading.excepthook = _quiet_writer_threads


class _LastCrc:
    """tensorboard's record checksum (masked CRC-32C, in pure Python: ~26 ms for Figure 2's 124 kB image event),
    remembered for the last large record: the runner writes the same image event, with one wall time
    (`OrderLog.shown`), to every order's log (16 in a population run), so it is computed once, not once per log.
    The same value either way; small records (scalars, text) are computed as before."""

    LARGE = 4096   # bytes: below this a record costs less to checksum than to compare

    def __init__(self, crc):
        self.crc, self.last, self.lock = crc, (None, None), threading.Lock()   # the logs' writer threads share it

    def __call__(self, data: bytes) -> int:
        if len(data) < self.LARGE:
            return self.crc(data)
        with self.lock:
            seen, value = self.last
            if seen != data:
                value = self.crc(data)
                self.last = (bytes(data), value)
            return value


if not isinstance(record_writer.masked_crc32c, _LastCrc):
    record_writer.masked_crc32c = _LastCrc(record_writer.masked_crc32c)


class OrderLog:
    """Writer for one order's run directory. `purge_step` drops events a killed run wrote past its checkpoint."""

    def __init__(self, logdir: Path, purge_step: int | None = None):
        self.logdir = Path(logdir)
        with self._named():
            self.writer = SummaryWriter(log_dir=str(logdir), purge_step=purge_step)

    @contextlib.contextmanager
    def _named(self):
        """An OSError without a file name (the writer thread's failed write, raised again here) names the log. A
        signal meanwhile takes effect when the call is done (train.common.exits.signals_held): raised inside the writer's
        queue it could leave the queue's lock held, and closing the log then waited for ever (seen once: SIGTERM at a
        goal trial's line)."""
        from train.common.exits import signals_held
        try:
            with signals_held():
                yield
        except OSError as e:
            if e.filename is None:
                e.filename = str(self.logdir)
            raise

    def hparams(self, params: dict, metrics: dict) -> None:
        clean = {k: (v if isinstance(v, (int, float, str, bool)) else str(v)) for k, v in params.items()}
        with self._named():
            for summary in hparams(clean, metrics):
                self.writer.file_writer.add_summary(summary)

    def episode(self, t: int, rec: dict) -> None:
        with self._named():
            self._episode(t, rec)

    def _episode(self, t: int, rec: dict) -> None:
        w, step = self.writer, t + 1
        for p in object_properties(rec["rules"]):
            w.add_scalar(f"certainty/{p}", rec["knowledge"][p]["certainty"], step)
            for r in RULE_NAMES:
                w.add_scalar(f"rules/{p}/{r}", float(rec["rules"][p] == r), step)
        if rec["predicted_cm3"] is not None:
            w.add_scalar("prediction/abs_error_cm3", abs(rec["predicted_cm3"] - rec["archimedes_cm3"]), step)
        if rec["probe_rel_error"] is not None:
            w.add_scalar("prediction/probe_rel_error", rec["probe_rel_error"], step)
        w.add_text("episodes", episode_line(t, rec), step)
        w.flush()

    def trial(self, i: int, rec: dict) -> None:
        with self._named():
            self._trial(i, rec)

    def _trial(self, i: int, rec: dict) -> None:
        w, step = self.writer, i + 1
        w.add_scalar("trials/drops", rec["drops"], step)
        w.add_scalar("trials/excess_drops", rec["excess_drops"], step)
        w.add_text("trials", trial_line(i, rec), step)
        w.flush()

    def image(self, tag: str, image, step: int) -> None:
        """An (H, W, 3) uint8 image at step."""
        with self._named():
            self.writer.add_image(tag, image, step, dataformats="HWC")

    @staticmethod
    def encoded(tag: str, image):
        """An (H, W, 3) uint8 image as SummaryWriter.add_image encodes it (a PNG): the runner encodes Figure 2 once
        for all its orders' logs (`shown`), not once per log."""
        return image_summary(tag, image, dataformats="HWC")

    def shown(self, encoded, step: int, walltime: float | None = None) -> None:
        """An image `encoded` gave, at step: what image(tag, image, step) writes. walltime: the event's (default:
        now); one for every log makes their events the same bytes, checksummed once (_LastCrc)."""
        with self._named():
            self.writer.file_writer.add_summary(encoded, step, walltime)

    def close(self) -> None:
        with self._named():
            self.writer.close()
