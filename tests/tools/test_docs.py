"""Docs that cannot rot: every Python block of the guide runs, every relative link and anchor
resolves, every command the guide names exists, the pages keep their sizes and the experiments
are indexed.

The Python blocks of README.md and of each page of docs/ run in order, in one namespace per
page, from the repository root, with one torch thread. A block that must not run carries, on
the line just before its fence, ``<!-- docs-test: skip (the reason) -->``; the reason is
required. Blocks in experiments/ record what was run and are not run."""

from __future__ import annotations

import re
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
GUIDE = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
EXPERIMENTS = sorted((ROOT / "experiments").rglob("*.md"))
LINKED = [*GUIDE, *sorted((ROOT / "docs").rglob("*/*.md")), *EXPERIMENTS, ROOT / "CHANGELOG.md"]
#: Pages written by commands (``make results``, ``make bench``): their sizes are the data's.
GENERATED = {"results.md", "performance.md"}
README_LINES, PAGE_LINES = 200, 600
SKIP = re.compile(r"<!--\s*docs-test:\s*skip\s*\((?P<reason>[^)]*)\)\s*-->")
FENCE = re.compile(r"^(?P<indent> *)(?P<fence>```+|~~~+)\s*(?P<lang>[\w+-]*)")


def rel(path: Path) -> str:
    try:
        return path.resolve().relative_to(ROOT).as_posix()
    except ValueError:
        return path.as_posix()


def blocks(path: Path) -> list[tuple[int, str, str, str | None]]:
    """``(line, language, code, skip reason)`` of every fenced block of ``path``."""
    lines = path.read_text().splitlines()
    out, i = [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        start, fence, indent = i, m["fence"], len(m["indent"])
        j = i + 1
        while j < len(lines) and not lines[j].strip().startswith(fence):
            j += 1
        code = "\n".join(line[indent:] for line in lines[start + 1:j])
        prev = next((lines[k] for k in range(start - 1, -1, -1) if lines[k].strip()), "")
        skip = SKIP.search(prev)
        out.append((start + 1, m["lang"].lower(), code, skip["reason"].strip() if skip else None))
        i = j + 1
    return out


def prose(path: Path, inline_code: bool = False) -> str:
    """``path``'s text without its fenced blocks, and without its inline code unless
    ``inline_code`` (links in code are not links; a heading's code is part of its anchor)."""
    text, kept, inside, fence = path.read_text(), [], False, ""
    for line in text.splitlines():
        m = FENCE.match(line)
        if m and not inside:
            inside, fence = True, m["fence"]
            continue
        if inside:
            if line.strip().startswith(fence):
                inside = False
            continue
        kept.append(line.replace("`", "") if inline_code else re.sub(r"`[^`]*`", "", line))
    return "\n".join(kept)


# ------------------------------------------------------------------------- the Python blocks
@pytest.mark.parametrize("page", [p for p in GUIDE if any(b[1] == "python" for b in blocks(p))],
                         ids=rel)
def test_python_blocks_run(page, monkeypatch):
    import torch

    monkeypatch.chdir(ROOT)
    monkeypatch.syspath_prepend(str(ROOT))
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    namespace: dict = {"__name__": f"docs_{page.stem}"}
    try:
        for line, lang, code, skip in blocks(page):
            if lang != "python":
                continue
            if skip is not None:
                assert len(skip) > 3, f"{rel(page)}:{line}: a skipped block needs a reason"
                continue
            t0 = time.perf_counter()
            try:
                exec(compile(code, f"{rel(page)}:{line}", "exec"), namespace)
            except Exception as exc:
                raise AssertionError(f"{rel(page)}, the block at line {line} fails: "
                                     f"{type(exc).__name__}: {exc}") from exc
            took = time.perf_counter() - t0
            assert took < 60, f"{rel(page)}:{line}: the block took {took:.0f} s (keep it cheap)"
    finally:
        torch.set_num_threads(threads)


def test_every_skipped_block_gives_its_reason():
    for page in GUIDE:
        text = page.read_text()
        for m in re.finditer(r"<!--\s*docs-test:[^>]*-->", text):
            assert SKIP.fullmatch(m[0]) and len(SKIP.fullmatch(m[0])["reason"].strip()) > 3, (
                f"{rel(page)}: {m[0]!r} is not '<!-- docs-test: skip (a reason) -->'")


# ----------------------------------------------------------------------- links and anchors
def slugs(path: Path) -> set[str]:
    """The anchors GitHub gives the headings of ``path`` (lower case, punctuation but ``-`` and
    ``_`` dropped, spaces to ``-``; a repeated heading gets ``-1``, ``-2``, ...), and the
    explicit ``<a id=...>`` / ``<a name=...>`` anchors."""
    seen: dict[str, int] = {}
    out = set(re.findall(r"<a\s+(?:id|name)=\"([^\"]+)\"", path.read_text()))
    for line in prose(path, inline_code=True).splitlines() if path.suffix == ".md" else []:
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", m[1])  # a link's text only
        text = re.sub(r"<[^>]+>", "", text)
        slug = re.sub(r"[^\w\- ]", "", text.lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def links(path: Path) -> list[str]:
    """The targets of the Markdown links and images of ``path``'s prose."""
    text = prose(path)
    found = re.findall(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)", text)
    found += re.findall(r"^\s*\[[^\]]+\]:\s*(\S+)", text, flags=re.M)  # reference links
    return found


def broken_links(path: Path) -> list[str]:
    bad = []
    for target in links(path):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        file, _, anchor = target.partition("#")
        dest = (path.parent / file).resolve() if file else path
        if not dest.exists():
            bad.append(f"{target}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in slugs(dest):
            bad.append(f"{target}: no heading with that anchor in {rel(dest)}")
    return bad


@pytest.mark.parametrize("page", LINKED, ids=rel)
def test_relative_links_and_anchors_resolve(page):
    bad = broken_links(page)
    assert not bad, f"{rel(page)}: " + "; ".join(bad)


def test_the_link_checker_finds_what_is_broken(tmp_path):
    page = tmp_path / "page.md"
    (tmp_path / "other.md").write_text("# A title: with `code`\n## Step 2.1 (the end)\n## A title: with code\n")
    page.write_text("[ok](other.md#a-title-with-code) [ok](other.md#step-21-the-end)\n"
                    "[ok](other.md#a-title-with-code-1) [ok](#here) [web](https://x.org/a#b)\n"
                    "# Here\n[bad](missing.md) [bad](other.md#nope) `[code](missing.md)`\n"
                    "```\n[in a block](missing2.md)\n```\n")
    bad = broken_links(page)
    assert len(bad) == 2 and bad[0] == "missing.md: no such file", bad
    assert bad[1].startswith("other.md#nope: no heading with that anchor"), bad


# ------------------------------------------------------------------------- commands named
def make_targets() -> set[str]:
    return set(re.findall(r"^([a-zA-Z][\w-]*):", (ROOT / "Makefile").read_text(), flags=re.M))


def code_text(path: Path) -> str:
    """The code of ``path``: its inline code spans and its shell and text blocks, one per line
    (prose says "make a choice"; code says ``make train``)."""
    spans = re.findall(r"`([^`\n]+)`", path.read_text())
    shell = [code for _, lang, code, _ in blocks(path) if lang in ("bash", "sh", "shell", "console", "")]
    return "\n".join([*spans, *shell])


def test_every_command_the_guide_names_exists():
    import importlib.util

    from agents.cli import COMMANDS

    targets, missing = make_targets(), []
    for page in GUIDE:
        text = code_text(page)
        for target in re.findall(r"(?:^|[\s;(&|])make ([a-z][\w-]*)", text, flags=re.M):
            if target not in targets:
                missing.append(f"{rel(page)}: make {target}")
        for command in re.findall(r"marl-vertiport ([a-z][\w-]*)", text):
            if command not in COMMANDS:
                missing.append(f"{rel(page)}: marl-vertiport {command}")
        for module in re.findall(r"python -m ((?:agents|marl_vertiport)[\w.]*)", text):
            if importlib.util.find_spec(module) is None:
                missing.append(f"{rel(page)}: python -m {module}")
    assert not missing, "commands the guide names that do not exist: " + ", ".join(missing)


# ------------------------------------------------------------------ sizes and the index
def test_the_readme_and_every_guide_page_keep_their_size():
    lines = {rel(p): len(p.read_text().splitlines()) for p in GUIDE}
    assert lines["README.md"] <= README_LINES, f"README.md has {lines['README.md']} lines"
    long = {p: n for p, n in lines.items() if p != "README.md" and Path(p).name not in GENERATED
            and n > PAGE_LINES}
    assert not long, f"guide pages over {PAGE_LINES} lines (move studies to experiments/): {long}"


def test_every_experiment_is_indexed_newest_first():
    index = (ROOT / "experiments" / "README.md").read_text()
    entries = re.findall(r"^- (\d{4}-\d{2}-\d{2}) \[([\w.-]+)\]\(([\w.-]+)/README\.md\): (.+)$",
                         index, flags=re.M)
    folders = sorted(p.name for p in (ROOT / "experiments").iterdir() if p.is_dir())
    assert sorted(slug for _, slug, _, _ in entries) == folders
    assert all(slug == link for _, slug, link, _ in entries)
    dates = [date for date, *_ in entries]
    assert dates == sorted(dates, reverse=True), "the index is newest first"
    for folder in folders:
        text = (ROOT / "experiments" / folder / "README.md").read_text()
        for part in ("**Question.**", "**Answer.**", "**Command.**", "**Commit.**", "**Seeds.**",
                     "**Data.**"):
            assert part in text, f"experiments/{folder}/README.md has no {part}"


def test_the_version_is_the_same_everywhere_and_the_changelog_has_it():
    """pyproject.toml, the package, CITATION.cff and the newest CHANGELOG entry name one
    version; every rules version of the env has its entry in the CHANGELOG."""
    import tomllib

    import marl_vertiport
    from marl_vertiport.config import RULES_VERSIONS

    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert marl_vertiport.__version__ == version
    assert re.search(rf"^version: {re.escape(version)}$", (ROOT / "CITATION.cff").read_text(),
                     flags=re.M)
    changelog = (ROOT / "CHANGELOG.md").read_text()
    releases = re.findall(r"^## \[(\d+\.\d+\.\d+)\]", changelog, flags=re.M)
    assert releases and releases[0] == version, f"the newest CHANGELOG entry is {releases[:1]}"
    for rules in RULES_VERSIONS:
        assert re.search(rf"^### v{rules}$", changelog, flags=re.M), f"no CHANGELOG entry for v{rules}"


#: Code a user copies: the guide's Python blocks, the examples, the adapters' docstring recipes.
RECIPE_FILES = [*sorted((ROOT / "examples").glob("*.py")),
                *sorted((ROOT / "agents" / "interop").glob("*_env.py"))]


def _uses_torch(code: str) -> bool:
    return bool(re.search(r"^\s*(import torch|from torch|from agents\.interop|import ray|"
                          r"from sb3_contrib|from torch_geometric)", code, re.M))


def test_every_recipe_that_runs_torch_sets_one_thread():
    """On these small batches torch's default threads are several times slower on a busy
    machine (experiments/torch-threads-small-batches): every block, example and recipe a user
    copies that runs torch sets one thread."""
    missing = []
    for page in GUIDE:
        for line, lang, code, _ in blocks(page):
            if lang == "python" and _uses_torch(code) and "set_num_threads(1)" not in code:
                missing.append(f"{rel(page)}:{line}")
    for path in RECIPE_FILES:
        text = path.read_text()
        if _uses_torch(text) and "set_num_threads(1)" not in text:
            missing.append(rel(path))
    assert not missing, f"sets no torch thread count: {missing}"


def test_the_ecosystem_page_quotes_every_library_the_benchmark_measures():
    from agents.bench.ecosystem import MEASURES

    text = (ROOT / "docs" / "ecosystem.md").read_text()
    assert not [name for name in MEASURES if f"`{name}`" not in text], \
        "docs/ecosystem.md quotes a speed for each row of make bench-ecosystem"
