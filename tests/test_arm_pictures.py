"""The pictures of the arm committed under results/arm/ are what README's documented command makes."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
ARM = ROOT / "results" / "arm"
BIN = Path(sys.executable).parent


def documented_command(scenario: str) -> str:
    """README's command for the pictures of ``scenario`` (its ``S`` replaced), without ``results/arm/``."""
    text = " ".join(ROOT.joinpath("README.md").read_text().split())
    match = re.search(r"Made with `(qpbench simulate --scenario S [^`]*)`", text)
    assert match, "README no longer documents how results/arm/ is made"
    return (
        match.group(1)
        .replace("results/arm/", "")
        .replace(" S ", f" {scenario} ")
        .replace("S.", f"{scenario}.")
    )


def _frames(path: Path) -> int:
    with Image.open(path) as im:
        return getattr(im, "n_frames", 1)


@pytest.mark.parametrize("gif", sorted(ARM.glob("*.gif")), ids=lambda p: p.name)
def test_committed_gifs_are_small(gif):
    assert gif.stat().st_size < 3 * 2**20
    assert _frames(gif) > 10


def test_documented_command_regenerates_the_free_pictures(tmp_path):
    command = documented_command("free")
    assert (
        command == "qpbench simulate --scenario free --backend daqp --snapshot free.png "
        "--animate free.gif --speed 4 --fps 12 --force"
    )
    proc = subprocess.run(
        [str(BIN / "qpbench"), *command.split()[1:]],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert proc.returncode == 0, proc.stderr
    for name in ("free.png", "free.gif"):
        made, committed = tmp_path / name, ARM / name
        with Image.open(made) as a, Image.open(committed) as b:
            assert a.size == b.size
        assert _frames(made) == _frames(committed)
        assert 0.7 < made.stat().st_size / committed.stat().st_size < 1.3


SHIPPED = sorted((ROOT / "results" / "arm").glob("*.png")) + sorted(
    (ROOT / "results" / "simulate").glob("*.png")
)


@pytest.mark.parametrize("png", SHIPPED, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_shipped_pictures_are_under_the_height_limit(png):
    from qpbench.report import style

    with Image.open(png) as im:
        assert im.size[1] <= style.MAX_HEIGHT_PX


def test_every_shipped_picture_has_its_command_beside_it():
    """Each picture under results/arm/ and results/simulate/ is named by the command its README gives."""
    readme = " ".join(ROOT.joinpath("README.md").read_text().split())
    network = re.search(r"`(qpbench simulate --scenario S --backend rnn-tuned [^`]*)`", readme)
    assert network, "README no longer documents how the network's pictures are made"
    made = set()
    for scenario in (
        "free",
        "wall",
        "adaptive",
        "narrow",
        "panda_table",
        "panda_shelf",
        "iiwa_wall",
    ):
        for command in (documented_command(scenario), network.group(1)):
            command = command.replace(" S ", f" {scenario} ").replace("/S", f"/{scenario}")
            made |= {w.replace("results/arm/", "") for w in command.split() if "." in w}
    assert {p.name for p in ARM.iterdir() if p.suffix in (".png", ".gif")} <= made
    simulate_readme = (ROOT / "results" / "simulate" / "README.md").read_text()
    for png in (ROOT / "results" / "simulate").glob("*.png"):
        assert f"--plot results/simulate/{png.name}" in simulate_readme
