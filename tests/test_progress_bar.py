"""The command line's progress bar: each stage of the work (its label) restarts the bar and is named."""

from napari_ssdpc import progress


def test_a_new_stage_is_named_and_restarts_the_bar(monkeypatch):
    bars = []

    class Recorded(progress.tqdm):  # the real bar, kept for the test to read
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            bars.append(self)

    monkeypatch.setattr(progress, "tqdm", Recorded)
    name = lambda bar: bar.desc.rstrip(": ")  # tqdm keeps "label: "
    with progress.tqdm_callback("refinement", unit="iteration") as update:
        update(30, 60, "TV")
        [bar] = bars
        assert (bar.n, bar.total, name(bar)) == (30, 60, "refinement (TV)")
        update(60, 60, "TV")
        update(5, 60, "multislice")
        assert (bar.n, bar.total, name(bar)) == (5, 60, "refinement (multislice)")
        update(7, 60)  # no label: the same stage
        assert (bar.n, name(bar)) == (7, "refinement (multislice)")
        update(2, 10)  # another total: the bar restarts
        assert (bar.n, bar.total) == (2, 10)


def test_a_new_stage_is_drawn_with_its_count_at_once(monkeypatch):
    """A stage that starts with work already done (the bead fit's coarse fit after its scan) reads
    1/3 at once, not 0/3 until the bar's next redraw (10 s in a log file, minutes for a bead fit)."""
    import io

    out = io.StringIO()
    monkeypatch.setattr(progress.sys, "stderr", out)
    with progress.tqdm_callback("refinement", unit="stage") as update:
        update(0, 3, "beads: scanning")
        update(1, 3, "beads: scanning")
        update(1, 3, "beads: coarse fit")
        drawn = out.getvalue().split("\r")[-1]
    assert "beads: coarse fit" in drawn and "1/3" in drawn, drawn
