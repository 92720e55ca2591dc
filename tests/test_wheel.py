"""The installed package: a wheel holds the design card's packages and `conag`, nothing else,
and the installed `conag` builds Fig. 6 from outside the source tree."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import venv
import zipfile

import pytest

from tests.conftest import ROOT

SHIPPED = {"protocol", "world_server", "agent_runtime", "teacher", "conag"}


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_the_wheel_installs_only_the_card_packages_and_builds_fig6(tmp_path):
    # Built from a copy of what git tracks: pip builds in the source tree (build/, egg-info).
    src = tmp_path / "src"
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    for name in filter(None, files.decode().split("\0")):
        if (ROOT / name).is_file():
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, src / name)
    dist = tmp_path / "dist"
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w",
                        str(dist), str(src)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    (wheel,) = dist.glob("conag-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    top = {n.split("/", 1)[0] for n in names if not n.split("/", 1)[0].endswith((".dist-info", ".data"))}
    assert top == SHIPPED, f"the wheel installs {sorted(top - SHIPPED)} beside the card's packages"
    assert "conag/viewer/static/index.html" in names  # the viewer's page ships with it

    # A clean venv that sees this machine's installed dependencies but not the source tree,
    # nor a PYTHONPATH that puts a checkout first (a worktree's tests run with one).
    env_dir = tmp_path / "venv"
    venv.EnvBuilder(system_site_packages=True, with_pip=True).create(env_dir)
    py = env_dir / "bin" / "python"
    clean = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    r = subprocess.run([str(py), "-m", "pip", "install", "--no-deps", "-q", str(wheel)], capture_output=True,
                       text=True, timeout=300, env=clean)
    assert r.returncode == 0, r.stdout + r.stderr
    scenario = tmp_path / "fig6.toml"
    scenario.write_text((ROOT / "scenarios" / "fig6.toml").read_text())
    run = subprocess.run([str(env_dir / "bin" / "conag"), "run", str(scenario), "--headless", "--quiet",
                          "--summary", str(tmp_path / "summary.json")],
                         cwd=tmp_path, capture_output=True, text=True, timeout=400, env=clean)
    assert run.returncode == 0, run.stdout + run.stderr
    import json

    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["completed"] and summary["sites_filled"] == summary["sites_total"] > 0
    # It ran the installed copy, not the checkout.
    where = subprocess.run([str(py), "-c", "import conag, world_server; print(conag.__file__, world_server.__file__)"],
                           cwd=tmp_path, capture_output=True, text=True, timeout=60, env=clean)
    assert str(ROOT) not in where.stdout and str(env_dir) in where.stdout, where.stdout
