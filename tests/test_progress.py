"""Progress: a tqdm bar on a terminal, start and end lines (and the story lines) in a log."""

import io

from train.common.progress import Step


class Terminal(io.StringIO):
    def isatty(self):
        return True


def test_a_terminal_gets_a_bar_with_counts_and_the_story_lines():
    out = Terminal()
    with Step("simulating", 3, "simulation", stream=out) as bar:
        for name in ("a", "b", "c"):
            bar.update(1, name)
        bar.line("episode 1/3: a")
    text = out.getvalue()
    assert "3/3" in text and "simulating" in text and "episode 1/3: a\n" in text and "\r" in text


def test_a_log_gets_plain_lines_only():
    out = io.StringIO()
    with Step("population", 5, "order", stream=out) as bar:
        for done in (2, 5):
            bar.to(done, 5)
    assert out.getvalue().splitlines()[0] == "population: 5 order(s)..."
    assert out.getvalue().splitlines()[1].startswith("population: done in ") and len(out.getvalue().splitlines()) == 2
    quiet = io.StringIO()
    with Step("episodes", 2, announce=False, stream=quiet) as bar:
        bar.update(1)
        bar.line("episode 1/2: a")
        bar.update(1)
    assert quiet.getvalue() == "episode 1/2: a\n"
