"""A generated suite of layouts as files: made on demand from a manifest, never committed.

A manifest (JSON, committed) names every layout by how the generator makes it: the
suite it belongs to (`generate_suite(count, seed)`), its index in that suite, and the
sha256 of its file; plus the generator version (`generator.GENERATOR_VERSION`) that
made it. `materialise(manifest, folder)` writes the files into `folder` (a cache: files
already there with the right checksum are kept, other `.toml` files are removed) and
refuses, naming the file, when the generator no longer makes what the manifest says.

    {"generator": 1,
     "layouts": [
      {"file": "000-gen-wall-20260000.toml", "count": 200, "suite_seed": 2026, "index": 0,
       "sha256": "..."},
      ...]}

A file is named `{index:03d}-{scenario name}.toml` (`file_name`). An entry may name a
family `mix` (`generator.SUITE_MIXES`: "solid" adds the solid shapes and corridors); none
is the version 1 mix, and its line then has no `mix` key.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

from world_server.files import write_text_whole
from world_server.generator import GENERATOR_VERSION, SUITE_MIXES, GeneratedScenario, generate, suite_plan


class SuiteError(RuntimeError):
    """The manifest and the generator disagree (a changed generator, or a bad manifest)."""


@dataclass(frozen=True)
class SuiteEntry:
    """One layout of a manifest: layout `index` of `generate_suite(count, suite_seed)`."""

    file: str
    count: int
    suite_seed: int
    index: int
    sha256: str
    mix: str = ""                     # the family mix of the suite (generator.SUITE_MIXES)

    def as_json(self) -> dict:
        """The entry as its manifest line holds it (no `mix` key for the version 1 mix)."""
        return {k: v for k, v in asdict(self).items() if k != "mix" or v}


@dataclass(frozen=True)
class Manifest:
    """A suite manifest: the generator version and every layout, in order."""

    generator: int                    # the GENERATOR_VERSION that made the layouts
    layouts: tuple[SuiteEntry, ...]

    def files(self) -> list[str]:
        """The layouts' file names, in the manifest's order."""
        return [e.file for e in self.layouts]

    def to_json(self) -> str:
        """The manifest file's text: one layout a line, so a change shows as the lines it changes."""
        rows = ",\n".join("  " + json.dumps(e.as_json()) for e in self.layouts)
        return f'{{"generator": {self.generator},\n "layouts": [\n{rows}\n ]}}\n'

    @classmethod
    def from_json(cls, text: str) -> Manifest:
        """The manifest a manifest file's text holds (SuiteError if it is not one)."""
        data = json.loads(text)
        try:
            return cls(int(data["generator"]), tuple(SuiteEntry(**e) for e in data["layouts"]))
        except (KeyError, TypeError) as exc:
            raise SuiteError(f"not a suite manifest: {exc}") from None


def file_name(index: int, g: GeneratedScenario) -> str:
    """`{index:03d}-{scenario name}.toml`: the suite's order, then what the layout is."""
    return f"{index:03d}-{g.name}.toml"


def sha256(text: str) -> str:
    """The checksum of a layout file's text, as the manifest holds it."""
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def generated(count: int, seed: int, indices: Iterable[int] | None = None,
              mix: str = "") -> Iterator[tuple[int, GeneratedScenario]]:
    """(index, layout) of `generate_suite(count, seed)` (with the families of `mix`), only
    those at `indices` if given (each is drawn on its own: layout i does not depend on the others)."""
    if mix not in SUITE_MIXES:
        raise SuiteError(f"unknown family mix {mix!r}; known: {', '.join(map(repr, SUITE_MIXES))}")
    plan = suite_plan(count, seed, families=SUITE_MIXES[mix])
    for i in range(count) if indices is None else indices:
        yield i, generate(**plan[i])


def manifest_of(suites: Iterable[tuple]) -> tuple[Manifest, dict[str, str]]:
    """A manifest of the layouts the generator makes now, and their texts by file name:
    `suites` holds (count, seed, indices or None for all[, family mix])."""
    entries, texts = [], {}
    for count, seed, indices, *rest in suites:
        mix = rest[0] if rest else ""
        for i, g in generated(count, seed, indices, mix):
            name = file_name(i, g)
            entries.append(SuiteEntry(name, count, seed, i, sha256(g.text), mix))
            texts[name] = g.text
    return Manifest(GENERATOR_VERSION, tuple(entries)), texts


def read_manifest(path: str | Path) -> Manifest:
    """The manifest in the file at `path`."""
    return Manifest.from_json(Path(path).read_text(encoding="utf-8"))


def _holds(path: Path, digest: str) -> bool:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest() == digest
    except OSError:
        return False


def materialise(manifest: str | Path | Manifest, folder: str | Path) -> list[Path]:
    """The manifest's layout files in `folder`, made where missing or different; returns
    their paths in the manifest's order. Raises SuiteError if the generator does not make
    exactly the manifest's files (a generator change: regenerate the manifest on purpose)."""
    m = manifest if isinstance(manifest, Manifest) else read_manifest(manifest)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    wanted = {e.file for e in m.layouts}
    for old in folder.glob("*.toml"):
        if old.name not in wanted:
            old.unlink()
    missing = [e for e in m.layouts if not _holds(folder / e.file, e.sha256)]
    if missing and m.generator != GENERATOR_VERSION:
        raise SuiteError(f"the manifest was made by generator version {m.generator}, this is version "
                         f"{GENERATOR_VERSION}: its layouts cannot be made again")
    by_suite: dict[tuple[int, int, str], list[SuiteEntry]] = {}
    for e in missing:
        by_suite.setdefault((e.count, e.suite_seed, e.mix), []).append(e)
    for (count, seed, mix), entries in by_suite.items():
        for e, (i, g) in zip(entries, generated(count, seed, [e.index for e in entries], mix)):
            if file_name(i, g) != e.file or sha256(g.text) != e.sha256:
                raise SuiteError(f"{e.file}: the generator (version {GENERATOR_VERSION}) now makes "
                                 f"{file_name(i, g)} with sha256 {sha256(g.text)[:12]}..., the manifest says "
                                 f"{e.sha256[:12]}...: a changed generator must bump GENERATOR_VERSION and "
                                 f"write a new manifest")
            write_text_whole(folder / e.file, g.text)  # two processes materialising at once
    return [folder / e.file for e in m.layouts]
