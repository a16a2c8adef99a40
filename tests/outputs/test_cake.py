"""``cake.png``: each tier says its layer and whether it is classical or learned, in words
and in colour, as ``layers`` says - read back from the figure and from a run's PNG."""

from __future__ import annotations

import numpy as np
from matplotlib.colors import to_rgb

from cake_drake.outputs.cake import COLOURS, LAYERS, cake_figure

MIXED = {
    "symbolic": {"kind": "learned", "what": "relational network, width 64: here"},
    "geometric": {"kind": "classical", "what": "WaypointIk, Drake IK"},
    "dynamic": {"kind": "learned", "what": "computed torque + learned residual"},
    "perception": {"kind": "classical", "what": "depth: colour, depth points, ICP"},
}


def _tiers(fig):
    """Each tier's patch (top to bottom) and the texts drawn inside it."""
    ax = fig.axes[0]
    boxes = [p for p in ax.patches if p.get_width() > 5][::-1]  # drawn bottom up
    out = []
    for box in boxes:
        x0, y0 = box.get_x(), box.get_y()
        inside = [t.get_text() for t in ax.texts
                  if x0 <= t.get_position()[0] <= x0 + box.get_width()
                  and y0 <= t.get_position()[1] <= y0 + box.get_height()]  # fmt: skip
        out.append((box, inside))
    return out


def test_each_tier_says_its_layer_and_kind_in_words_and_colour():
    truth = {**MIXED, "perception": {"kind": "truth", "what": "the simulator's own poses"}}
    three = {n: MIXED[n] for n in LAYERS[:3]}  # a summary from before the perception layer
    for layers in (MIXED, {n: {**MIXED[n], "kind": "classical"} for n in LAYERS}, truth, three):
        tiers = _tiers(cake_figure(layers, "a title"))
        assert len(tiers) == len(layers)
        for name, (box, texts) in zip(LAYERS, tiers, strict=False):
            kind = layers[name]["kind"]
            assert f"{name.upper()}  ·  {kind}" in texts, texts
            assert any(layers[name]["what"] in t for t in texts), texts
            assert np.allclose(box.get_facecolor()[:3], to_rgb(COLOURS[kind]))


def test_the_png_shows_each_tier_in_its_kinds_colour(tmp_path):
    from matplotlib.image import imread

    from cake_drake.outputs.cake import write_cake

    write_cake(MIXED, tmp_path / "cake.png")
    image = imread(tmp_path / "cake.png")[:, :, :3]
    fig = cake_figure(MIXED)
    ax, height = fig.axes[0], image.shape[0]
    for name, (box, _) in zip(LAYERS, _tiers(fig), strict=True):
        # A point inside the tier, clear of its words: near its lower right corner.
        x, y = box.get_x() + box.get_width() - 0.4, box.get_y() + 0.15
        px, py = ax.transData.transform((x, y))
        colour = image[int(height - py), int(px)]
        assert np.allclose(colour, to_rgb(COLOURS[MIXED[name]["kind"]]), atol=0.02), name
