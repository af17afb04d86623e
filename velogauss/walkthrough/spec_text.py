"""The spec as the walkthrough quotes it: spec/index.toml's entries, each section's own text.

The walkthrough quotes the spec verbatim instead of paraphrasing it, so a formula can only
differ from the spec by the spec changing, and then the regeneration check fails until the
walkthrough is rebuilt.
"""

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
INDEX = ROOT / "spec" / "index.toml"


def index_entries():
    """The equations of spec/index.toml, in its order: dicts with id, title, section, ref, fast."""
    return tomllib.loads(INDEX.read_text(encoding="utf-8"))["equation"]


def spec_file_title(section):
    """The title of a spec file (its `# ` heading, without "(normative)"), e.g. "Motion: ..."."""
    for line in _lines(section):
        if line.startswith("# "):
            return line[2:].replace("(normative)", "").strip()
    raise ValueError(f"{section}: no '# ' title line")


def spec_file_preamble(section):
    """The text of a spec file between its title and its first `---` or `## ` line."""
    lines = _lines(section)
    start = next(i for i, line in enumerate(lines) if line.startswith("# ")) + 1
    return _until_next_section(lines, start)


def equation_text(section, spec_id):
    """The body of the `## <spec_id> — ...` section of a spec file, up to the next section.

    Raises ValueError naming the file when it has no section for `spec_id`.
    """
    lines = _lines(section)
    heading = f"## {spec_id} "
    starts = [i for i, line in enumerate(lines) if line.startswith(heading)]
    if not starts:
        raise ValueError(f"{section}: no section '{heading}...'")
    return _until_next_section(lines, starts[0] + 1)


def _lines(section):
    return (ROOT / section).read_text(encoding="utf-8").splitlines()


def _until_next_section(lines, start):
    end = next((i for i in range(start, len(lines)) if lines[i].startswith(("## ", "---"))), len(lines))
    return "\n".join(lines[start:end]).strip("\n")


def blockquote(text):
    """`text` as a Markdown blockquote (every line prefixed; blank lines keep the quote open)."""
    return "\n".join(f"> {line}" if line else ">" for line in text.split("\n"))
