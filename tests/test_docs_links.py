"""Every relative link in README.md, ARCHITECTURE.md and docs/*.md points to a file that exists (and to a
heading of it, when the link names one): the README is the front door to docs/, a moved page must not
leave a dead link behind."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
FENCE = re.compile(r"^(```|~~~)")


def markdown_files(root: Path) -> list[Path]:
    """The pages whose links are checked."""
    pages = [root / "README.md", root / "ARCHITECTURE.md", *sorted((root / "docs").glob("*.md"))]
    return [page for page in pages if page.is_file()]


def prose(text: str) -> str:
    """``text`` without fenced code blocks and inline code (their brackets are not links)."""
    kept, fenced = [], False
    for line in text.splitlines():
        if FENCE.match(line.strip()):
            fenced = not fenced
            continue
        if not fenced:
            kept.append(re.sub(r"`[^`]*`", "", line))
    return "\n".join(kept)


def anchors(page: Path) -> set[str]:
    """The heading anchors GitHub makes for ``page``: lower case, punctuation dropped, spaces to hyphens."""
    seen: dict[str, int] = {}
    result = set()
    in_fence = False
    for line in page.read_text(encoding="utf-8").splitlines():
        if FENCE.match(line.strip()):
            in_fence = not in_fence
            continue
        heading = None if in_fence else re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if heading:
            slug = re.sub(r"[^\w\- ]", "", heading.group(1).strip().lower()).replace(" ", "-")
            count = seen.get(slug, 0)
            seen[slug] = count + 1
            result.add(slug if count == 0 else f"{slug}-{count}")
    return result


def broken_links(pages: list[Path]) -> list[str]:
    """One line per relative link of ``pages`` whose file (or heading) does not exist."""
    broken = []
    for page in pages:
        for target in LINK.findall(prose(page.read_text(encoding="utf-8"))):
            if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.IGNORECASE):  # http:, https:, mailto:
                continue
            path, _, fragment = target.partition("#")
            linked = (page.parent / path).resolve() if path else page
            if not linked.exists():
                broken.append(f"{page.name}: {target}: no such file")
            elif fragment and linked.suffix == ".md" and fragment not in anchors(linked):
                broken.append(f"{page.name}: {target}: no such heading in {linked.name}")
    return broken


def test_every_relative_link_resolves():
    pages = markdown_files(REPO)
    assert REPO / "README.md" in pages and len(pages) >= 3
    assert broken_links(pages) == []


def test_a_broken_link_is_reported(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "README.md").write_text(
        "# Start\n[cli](docs/cli.md) [gone](docs/gone.md) [here](#start) [nowhere](#nowhere)\n"
        "```\n[in code](docs/also-gone.md)\n```\n[web](https://example.org/x.md)\n",
        encoding="utf-8",
    )
    (tmp_path / "docs" / "cli.md").write_text(
        "# The `estimate` command\n[back](../README.md#start) [bad](../README.md#end) [self](#the-estimate-command)\n",
        encoding="utf-8",
    )
    assert broken_links(markdown_files(tmp_path)) == [
        "README.md: docs/gone.md: no such file",
        "README.md: #nowhere: no such heading in README.md",
        "cli.md: ../README.md#end: no such heading in README.md",
    ]
