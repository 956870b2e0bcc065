"""Each shipped model against its card: the card's golden check (a small committed file, its
median errors at one frame) recomputed here. Any change to what a shipped model predicts (a sign
convention, a feature, the canonical frame, the mesh options) moves these numbers."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from fignet_gym.cli import main
from fignet_gym.data.format import load_trajectories
from fignet_gym.pretrained import available_pretrained, load_pretrained, pretrained_dir
from fignet_gym.train.evaluation import rollout_metrics

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = re.compile(r"## Golden check\n`(?P<file>[^`]+)`.*?medians at frame (?P<h>\d+): translation "
                    r"RMSE (?P<t>[\d.]+) mm, rotation (?P<r>[\d.]+) deg", re.S)
#: Cross-CPU rounding moves these errors by about 1e-3 (tosses bounce: more); a changed model by
#: far more.
RTOL = 0.05


def _data(path: Path, tmp: Path) -> Path:
    """The card's file; a committed raw sample folder is imported as its card says."""
    if path.is_file():
        return path
    out = tmp / f"{path.name}.h5"
    if "contactnets" in path.name:
        assert main(["import-contactnets", str(path), "--out", str(out)]) == 0
    else:
        assert main(["import-mit", str(path), "--out", str(out), "--dt", "0.02"]) == 0
    return out


@pytest.mark.parametrize("name", available_pretrained())
def test_shipped_model_scores_what_its_card_says(name: str, tmp_path: Path) -> None:
    card = (pretrained_dir() / f"{name}.md").read_text()
    m = GOLDEN.search(card)
    assert m, f"{name}.md has no golden check"
    trajs = load_trajectories(_data(ROOT / m["file"], tmp_path))
    res = rollout_metrics(load_pretrained(name), trajs, horizon=int(m["h"]))
    assert 1e3 * res["translation_rmse_final"] == pytest.approx(float(m["t"]), rel=RTOL)
    assert res["rotation_deg_final"] == pytest.approx(float(m["r"]), rel=RTOL)
