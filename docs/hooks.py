"""MkDocs hooks of the ConAg docs site (mkdocs.yml: `hooks:`).

* `<!-- conag-cli -->` in a page becomes the `--help` of `conag` and of every subcommand,
  taken from `conag.cli.build_parser()` at build time, so the reference cannot drift.
* `<!-- include PATH -->` on a line of its own becomes the text of PATH (relative to the
  page), e.g. CHANGELOG.md or deploy/README.md, which stay where they are for GitHub readers.
* A link from a page to a file of the repository outside docs/ (`../../scenarios/fig6.toml`,
  a picture of experiments/) works on GitHub as it is; on the site it is rewritten to a copy
  of that file under `_repo/` (a markdown file is rendered as a page there), or, for the
  files a page of the site already carries (deploy/README.md, examples/), to that page.
  A link to a file that does not exist is a warning, so `mkdocs build --strict` fails on it.
* The results pages' pictures under experiments/ are made, not committed: before the build,
  those missing are drawn (`python3 -m experiments.pictures`, a minute or so on a fresh clone).
"""

from __future__ import annotations

import io
import logging
import os
import re
import sys
from contextlib import redirect_stdout
from pathlib import Path

from mkdocs.structure.files import File

log = logging.getLogger("mkdocs.plugins.conag_hooks")

# Repository files whose content a page of the site carries: links to them go to that page.
CARRIED = {
    "deploy/README.md": "how-to/deploy.md",
    "deploy": "how-to/deploy.md",
    "examples/README.md": "how-to/own-agent.md",
    "examples": "how-to/own-agent.md",
    "CHANGELOG.md": "changelog.md",
    "README.md": "index.md",
}
REPO_DIR = "_repo"  # where copies of repository files outside docs/ go on the site

LINK = re.compile(r"(!?\[[^\]]*\]\()([^)\s]+)(\s+\"[^\"]*\")?\)")
INCLUDE = re.compile(r"^<!-- include (\S+) -->$", re.MULTILINE)
CLI_MARKER = "<!-- conag-cli -->"
CODE_SPAN = re.compile(r"(`+)(?:(?!\1).)+?\1")

_real: dict[str, Path] = {}  # src_uri of a generated page -> the repository file it renders


def _root(config) -> Path:
    return Path(config.config_file_path).resolve().parent


def _outside_code(text: str):
    """Yield (is_code, chunk) over `text`: fenced and indented code blocks are code."""
    fence = None
    for line in text.splitlines(keepends=True):
        stripped = line.lstrip()
        if fence is None and stripped.startswith(("```", "~~~")):
            fence = stripped[:3]
            yield True, line
            continue
        if fence is not None:
            if stripped.startswith(fence):
                fence = None
            yield True, line
            continue
        # an indented code block, not a list item's text
        if (line.startswith("    ") and line.strip() and not re.match(r"\s*([*+-]|\d+\.)\s", line)
                and not LINK.search(line)):
            yield True, line
            continue
        yield False, line


def _links(line: str):
    """The link matches of a line of text that do not start inside an inline code span."""
    spans = [m.span() for m in CODE_SPAN.finditer(line)]
    for m in LINK.finditer(line):
        if not any(a <= m.start() < b for a, b in spans):
            yield m


def _targets(text: str):
    for is_code, chunk in _outside_code(text):
        if not is_code:
            for m in _links(chunk):
                yield m.group(2)


def _local(target: str) -> bool:
    return not (re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", target) or target.startswith(("#", "/")))


def _resolve(target: str, real_dir: Path, config, warn=log.warning) -> tuple[str | None, str]:
    """The site URI (relative to docs/) a local link target stands for, and its #fragment."""
    path, _, frag = target.partition("#")
    frag = "#" + frag if frag else ""
    if not path:
        return None, frag
    docs = Path(config.docs_dir).resolve()
    root = _root(config)
    real = (real_dir / path).resolve()
    if real.is_relative_to(docs):
        return real.relative_to(docs).as_posix(), frag
    if not real.is_relative_to(root):
        warn("link %r points outside the repository", target)
        return None, frag
    rel = real.relative_to(root).as_posix()
    if rel in CARRIED:
        return CARRIED[rel], frag
    if real.is_dir():
        if (real / "README.md").is_file():
            return f"{REPO_DIR}/{rel}/README.md", frag
        warn("link %r points to a directory without a README.md", target)
        return None, frag
    if not real.exists():
        warn("link %r points to %s, which does not exist", target, rel)
        return None, frag
    return f"{REPO_DIR}/{rel}", frag


def _rewrite(text: str, real_dir: Path, page_dir: str, config, where: str = "") -> str:
    out = []
    for is_code, chunk in _outside_code(text):
        if is_code:
            out.append(chunk)
            continue

        def sub(m):
            target = m.group(2)
            if not _local(target):
                return m.group(0)
            uri, frag = _resolve(target, real_dir, config, warn=lambda msg, *a: log.warning("%s: %s", where, msg % a))
            if uri is None:
                return m.group(0)
            new = os.path.relpath(uri, page_dir or ".").replace(os.sep, "/")
            return f"{m.group(1)}{new}{frag}{m.group(3) or ''})"

        pos, parts = 0, []
        for m in _links(chunk):
            parts += [chunk[pos:m.start()], sub(m)]
            pos = m.end()
        out.append("".join(parts) + chunk[pos:])
    return "".join(out)


def _expand_includes(text: str, real_dir: Path, page_dir: str, config) -> str:
    def sub(m):
        path = (real_dir / m.group(1)).resolve()
        if not path.is_file():
            log.warning("include %r: no such file", m.group(1))
            return m.group(0)
        return _rewrite(path.read_text(encoding="utf-8"), path.parent, page_dir, config, where=m.group(1))

    return INCLUDE.sub(sub, text)


def _cli_reference(root: Path) -> str:
    os.environ.setdefault("COLUMNS", "100")
    _import_path(root)
    from conag.cli import build_parser

    parser = build_parser()
    parts = ["## conag\n", "```text\n" + parser.format_help() + "```\n"]
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    for name, command in sub.choices.items():
        buf = io.StringIO()
        with redirect_stdout(buf):
            command.print_help()
        parts.append(f"## conag {name}\n")
        parts.append("```text\n" + buf.getvalue() + "```\n")
    return "\n".join(parts)


def _import_path(root: Path) -> None:
    if str(root) not in sys.path:  # this checkout's packages, whichever ones pip installed
        sys.path.insert(0, str(root))


def on_pre_build(config, **_):
    """Draw the pictures of experiments/ the pages link to that are not there yet."""
    _import_path(_root(config))
    from experiments import pictures

    names = pictures.missing()
    if names:
        log.info("drawing %s (python3 -m experiments.pictures)", ", ".join(names))
        pictures.draw(names)


def on_files(files, config):
    """Add a copy of every repository file outside docs/ that a page links to."""
    docs = Path(config.docs_dir).resolve()
    root = _root(config)
    todo = [(Path(f.abs_src_path), f.src_uri) for f in files.documentation_pages()]
    seen: set[str] = set()
    while todo:
        real, _ = todo.pop()
        text = real.read_text(encoding="utf-8")
        for m in INCLUDE.finditer(text):
            inc = (real.parent / m.group(1)).resolve()
            if inc.is_file():
                todo.append((inc, ""))
        for target in _targets(text):
            if not _local(target):
                continue
            uri, _ = _resolve(target, real.parent, config, warn=log.debug)  # warned once, by the page
            if uri is None or not uri.startswith(REPO_DIR + "/") or uri in seen:
                continue
            seen.add(uri)
            src = root / uri[len(REPO_DIR) + 1:]
            if src.is_relative_to(docs):
                continue
            files.append(File.generated(config, uri, abs_src_path=str(src)))
            if uri.endswith(".md"):
                _real[uri] = src
                todo.append((src, uri))
    return files


def on_page_markdown(markdown, page, config, **_):
    """Expand the CLI marker and includes; point links outside docs/ at their site copies."""
    src_uri = page.file.src_uri
    real = _real.get(src_uri, Path(page.file.abs_src_path))
    page_dir = os.path.dirname(src_uri)
    if CLI_MARKER in markdown:
        markdown = markdown.replace(CLI_MARKER, _cli_reference(_root(config)))
    markdown = _rewrite(markdown, real.parent, page_dir, config, where=src_uri)
    return _expand_includes(markdown, real.parent, page_dir, config)
