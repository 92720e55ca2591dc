"""The `conag` argument parser, without starting anything: what a user types is what it reads."""

from __future__ import annotations

import logging

import pytest

from conag.cli import build_parser, log_level


@pytest.mark.parametrize("argv, level", [
    (["status"], logging.WARNING),
    (["-v", "status"], logging.INFO),
    (["status", "-v"], logging.INFO),        # after the subcommand as well as before
    (["status", "-vv"], logging.DEBUG),
    (["-v", "world", "x.toml", "--verbose"], logging.DEBUG),  # before and after add up
    (["perturb", "add", "--at", "1,2", "-v"], logging.INFO),
])
def test_verbosity_is_accepted_before_and_after_the_subcommand(argv, level):
    assert log_level(build_parser().parse_args(argv)) == level


def test_perturb_force_reaches_the_request():
    args = build_parser().parse_args(["perturb", "add", "--at", "2.5,5.5", "--force"])
    assert args.force and not build_parser().parse_args(["perturb", "add", "--at", "2.5,5.5"]).force
