"""The example agents of examples/: each fills a site of quick_wall against a real `conag
world` process; the plain one needs nothing but zenoh and msgpack."""

from __future__ import annotations

import ast
import subprocess
import sys

import pytest

from protocol import keys
from protocol.codec import decode
from protocol.messages import WorldStatus
from tests.conftest import ROOT, SCENARIOS, Bus, Process, free_port, wait_until

EXAMPLES = ROOT / "examples"


def _imports(path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names}
    names |= {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.module}
    return {name.split(".")[0] for name in names}


def test_the_plain_agent_imports_only_zenoh_msgpack_and_the_standard_library():
    path = EXAMPLES / "raw_agent.py"
    assert _imports(path) - set(sys.stdlib_module_names) == {"zenoh", "msgpack"}
    assert len(path.read_text(encoding="utf-8").splitlines()) <= 80


def test_the_protocol_agent_uses_the_protocol_package_and_zenoh_only():
    assert _imports(EXAMPLES / "protocol_agent.py") - set(sys.stdlib_module_names) == {"zenoh", "protocol"}


@pytest.mark.slow
@pytest.mark.parametrize("example", ["raw_agent.py", "protocol_agent.py"])
def test_the_example_agent_fills_a_site_of_quick_wall(example):
    ep = f"tcp/127.0.0.1:{free_port()}"
    world = Process("world", str(SCENARIOS / "quick_wall.toml"), "--ticks", "100000000", "--listen", ep)
    bus = Bus(ep)
    try:
        world.wait_for("world w0: quick_wall")
        agent = subprocess.run([sys.executable, str(EXAMPLES / example), "--connect", ep, "--id", "x1"],
                               cwd=ROOT, capture_output=True, text=True, timeout=120)
        assert agent.returncode == 0, agent.stdout + agent.stderr
        assert "dropped a brick" in agent.stdout
        session = bus.client_session()

        def filled() -> int:
            replies = list(session.get(keys.status("w0"), timeout=2.0))
            return replies and decode(replies[0].ok.payload.to_bytes(), WorldStatus).sites_filled

        wait_until(lambda: filled() == 1, what="the world's status to count the site filled")
    finally:
        bus.close()
        world.kill()
