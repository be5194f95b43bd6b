#!/usr/bin/env python3
"""Check the relative links of Markdown files: each must name a file or folder that exists, and a
`#anchor` into a Markdown file must name one of its headings (GitHub's slugs: lower case,
punctuation dropped, spaces as hyphens, `-1`, `-2`, ... on repeats) or an explicit `id`/`name`.

Links inside code (fenced blocks, `inline code`) are not links and are skipped, as are absolute
URLs (`https:`, `mailto:`, ...). Prints every broken link as FILE:LINE and exits 1 if any.

Usage: scripts/check-links.py FILE.md...
"""

from __future__ import annotations

import re
import sys
import unicodedata
from pathlib import Path
from urllib.parse import unquote

FENCE = re.compile(r"^ {0,3}(`{3,}|~{3,})")
INLINE_CODE = re.compile(r"(`+)(?:(?!\1).)+?\1")
# [text](target "title") and ![alt](target); the target may be written <like this>.
INLINE_LINK = re.compile(
    r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]"  # the text, which may hold [brackets]
    r"\(\s*(<[^>]*>|[^)\s]+)(?:\s+[\"'(][^)]*)?\)"  # the target, then an optional title
)
REFERENCE = re.compile(r"^ {0,3}\[[^\]]+\]:\s*(<[^>]*>|\S+)")
HTML_LINK = re.compile(r"<(?:a|img)\s[^>]*?\b(?:href|src)\s*=\s*[\"']([^\"']+)[\"']", re.I)
HTML_ID = re.compile(r"<[a-z]+\s[^>]*?\b(?:id|name)\s*=\s*[\"']([^\"']+)[\"']", re.I)
HEADING = re.compile(r"^ {0,3}(#{1,6})\s+(.*?)(?:\s+#+)?\s*$")
SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")


def prose_lines(text: str):
    """(line number, line) outside fenced code blocks."""
    fence = None
    for number, line in enumerate(text.splitlines(), 1):
        m = FENCE.match(line)
        if fence is None and m:
            fence = m.group(1)
        elif fence is not None and line.strip().startswith(fence):
            fence = None
        elif fence is None:
            yield number, line


def slug(heading: str) -> str:
    """GitHub's anchor for a heading's text."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link's text stays
    text = re.sub(r"<[^>]+>", "", text).replace("`", "").lower()
    kept = []
    for c in text:
        category = unicodedata.category(c)
        if c in "-_" or c == " " or category[0] in "LNM":
            kept.append("-" if c == " " else c)
    return "".join(kept)


def anchors(path: Path, cache: dict[Path, set[str]]) -> set[str]:
    if path not in cache:
        found: set[str] = set()
        seen: dict[str, int] = {}
        text = path.read_text(encoding="utf-8")
        for _, line in prose_lines(text):
            if m := HEADING.match(line):
                base = slug(m.group(2))
                n = seen.get(base, 0)
                seen[base] = n + 1
                found.add(base if n == 0 else f"{base}-{n}")
            found.update(m.group(1) for m in HTML_ID.finditer(line))
        cache[path] = found
    return cache[path]


def targets(line: str):
    line = INLINE_CODE.sub(lambda m: " " * len(m.group(0)), line)
    for pattern in (INLINE_LINK, REFERENCE, HTML_LINK):
        for m in pattern.finditer(line):
            yield m.group(1).strip("<>")


def check(md: Path, cache: dict[Path, set[str]]) -> list[str]:
    broken = []
    for number, line in prose_lines(md.read_text(encoding="utf-8")):
        for target in targets(line):
            if SCHEME.match(target) or target.startswith("//"):
                continue
            path_part, _, anchor = target.partition("#")
            path = (md.parent / unquote(path_part)).resolve() if path_part else md.resolve()
            where = f"{md}:{number}: {target}"
            if not path.exists():
                broken.append(f"{where}: no such file or folder ({path})")
            elif anchor and path.suffix == ".md" and unquote(anchor) not in anchors(path, cache):
                broken.append(f"{where}: {path.name} has no heading with that anchor")
    return broken


def main() -> int:
    cache: dict[Path, set[str]] = {}
    broken = [b for name in sys.argv[1:] for b in check(Path(name), cache)]
    for b in broken:
        print(b)
    count = len(sys.argv) - 1
    print(f"relative links: {count} files, {len(broken)} broken", file=sys.stderr)
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main())
