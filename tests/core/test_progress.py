"""The progress bars behind ``progress=True``: one per stage, closed as its count reaches the total."""

from tqdm.auto import tqdm

from flockkit._progress import progress_bar


def open_bars():
    return [bar for bar in list(getattr(tqdm, "_instances", ())) if not bar.disable]


def test_a_bar_closes_when_its_stage_is_done():
    before = len(open_bars())
    with progress_bar(True) as report:
        report(0, 3, "bounding")
        assert len(open_bars()) == before + 1
        report(2, 3, "bounding")
        assert len(open_bars()) == before + 1
        report(3, 3, "bounding")
        assert len(open_bars()) == before  # its time stops with its work, not at the next stage
        report(1, 4, "difference matrix")
        assert len(open_bars()) == before + 1
    assert len(open_bars()) == before
