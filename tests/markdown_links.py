"""The relative links of Markdown pages, and which of them do not resolve.

Shared by test_readme.py (the pages of the repository) and test_install.py (the pages of an
installed copy): a link names a file relative to its page, and an anchor (#...) on a Markdown
page names one of that page's headings, as GitHub makes them.
"""

from __future__ import annotations

import re
from pathlib import Path

_CODE_BLOCK = re.compile(r"^[ \t]*```.*?^[ \t]*```", flags=re.S | re.M)


def heading_anchors(markdown: str) -> set[str]:
    """GitHub's anchors of the headings of a Markdown text (code blocks skipped)."""
    anchors: set[str] = set()
    seen: dict[str, int] = {}
    for title in re.findall(r"^#{1,6}\s+(.+?)\s*#*\s*$", _CODE_BLOCK.sub("", markdown),
                            flags=re.M):
        slug = re.sub(r"[^\w\- ]", "", title.strip().lower()).replace(" ", "-")
        count = seen.get(slug, 0)
        seen[slug] = count + 1
        anchors.add(slug if count == 0 else f"{slug}-{count}")
    return anchors


def relative_links(markdown: str) -> list[str]:
    """The link and image targets of a Markdown text that are not URLs (code blocks skipped)."""
    outside = _CODE_BLOCK.sub("", markdown)
    targets = re.findall(r"\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)", outside)
    targets += re.findall(r"<img[^>]*\ssrc=\"([^\"]+)\"", outside)
    return [t for t in targets if not re.match(r"[a-z]+:", t)]


def broken_links(page: Path, within: Path | None = None) -> list[str]:
    """One line per relative link of `page` that names no file, or no heading of its page, or
    (with `within`) a file outside the folder `within`."""
    problems = []
    for target in relative_links(page.read_text(encoding="utf-8")):
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if not file.exists():
            problems.append(f"{target}: no file {file}")
        elif within is not None and not file.is_relative_to(within.resolve()):
            problems.append(f"{target}: {file} is outside {within}")
        elif anchor and file.suffix == ".md":
            if anchor not in heading_anchors(file.read_text(encoding="utf-8")):
                problems.append(f"{target}: no heading with anchor #{anchor} in {file.name}")
    return problems
