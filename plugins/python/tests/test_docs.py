"""The README and docs/*.md run as written: every sh and python block, in order per document,
in a fresh temporary folder with the checkout's examples/ beside it, as in a clean checkout
(built-in robots, truths and paths are taken by name and need not even that). A block that truly cannot run there (it builds the project
itself) is preceded by `<!-- not run: reason -->`. Also: no product text points at a document
that is not in the product, and help texts speak of the product, not of how it is made."""
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
DOCS = [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))
RUN = {"sh": "sh", "bash": "sh", "shell": "sh", "console": "sh", "python": "python"}
NOT_RUN = re.compile(r"<!--\s*not run:\s*(\S.*?)\s*-->")


def code_blocks(md: Path):
    """(language, code, first line, reason not to run or None) of every fenced block."""
    lines = md.read_text(encoding="utf-8").splitlines()
    out, i = [], 0
    while i < len(lines):
        m = re.match(r"^```(\w*)\s*$", lines[i])
        if not m:
            i += 1
            continue
        start, lang = i, m.group(1)
        j = i + 1
        while j < len(lines) and not lines[j].startswith("```"):
            j += 1
        k = start - 1
        while k >= 0 and not lines[k].strip():
            k -= 1
        skip = NOT_RUN.search(lines[k]) if k >= 0 else None
        out.append((lang, "\n".join(lines[start + 1:j]), start + 1, skip.group(1) if skip else None))
        i = j + 1
    return out


def _runnable(md):
    return [b for b in code_blocks(md) if b[0] in RUN]


@pytest.mark.parametrize("md", [d for d in DOCS if _runnable(d)], ids=lambda p: p.name)
def test_document_commands_run_as_written(md, tmp_path):
    env = dict(os.environ)
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    env["MPLBACKEND"] = "Agg"
    (tmp_path / "examples").symlink_to(ROOT / "examples")  # as in a clean checkout
    ran = 0
    for lang, code, line, skip in _runnable(md):
        if skip:
            continue
        if RUN[lang] == "sh":
            cmd = ["bash", "-e", "-o", "pipefail", "-c", code]
        else:
            cmd = [sys.executable, "-c", code]
        p = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True)
        assert p.returncode == 0, (
            f"{md.name}:{line}: the {lang} block failed ({p.returncode}):\n{code}\n"
            f"--- stdout\n{p.stdout[-3000:]}\n--- stderr\n{p.stderr[-3000:]}")
        ran += 1
    assert ran > 0


def test_skipped_blocks_say_why():
    for md in DOCS:
        for lang, code, line, skip in code_blocks(md):
            if skip is not None:
                assert lang in RUN and len(skip) > 10, f"{md.name}:{line}"


# ---------------------------------------------------------------- links and references

PRODUCT_TEXT = ([ROOT / "README.md", ROOT / "TESTING.md", ROOT / "CHANGELOG.md"]
                + sorted((ROOT / "docs").rglob("*.md"))
                + sorted((ROOT / "plugins" / "python" / "stiff").rglob("*.py"))
                + sorted((ROOT / "libstiff").rglob("*.[ch]pp"))
                + sorted((ROOT / "capi").rglob("*.[ch]*"))
                + sorted((ROOT / "fmu").rglob("*.[ch]*"))
                + sorted((ROOT / "examples").rglob("*.*")))
MD_NAME = re.compile(r"(?<![\w/.-])((?:\.\./)?[\w./-]*[\w-]+\.md)\b")


def _shipped_markdown():
    return {p.relative_to(ROOT).as_posix() for p in ROOT.rglob("*.md")
            if ".venv" not in p.parts and "build" not in p.parts[:1]}


def test_no_reference_to_documents_outside_the_product():
    shipped = _shipped_markdown()
    names = {Path(s).name for s in shipped}
    bad = []
    for f in PRODUCT_TEXT:
        if not f.is_file() or f.suffix in (".png", ".csv", ".fmu"):
            continue
        text = f.read_text(encoding="utf-8", errors="replace")
        for n, line in enumerate(text.splitlines(), 1):
            for m in MD_NAME.finditer(line):
                ref = m.group(1)
                if ref.startswith(("/", "build-", "build/")):  # outputs: /tmp/..., build folders
                    continue
                if Path(ref).name not in names:
                    bad.append(f"{f.relative_to(ROOT)}:{n}: {ref}")
    assert not bad, "references to documents that are not in the product:\n" + "\n".join(bad)


def test_markdown_links_resolve():
    bad = []
    for md in [ROOT / "README.md", ROOT / "TESTING.md"] + sorted((ROOT / "docs").rglob("*.md")):
        for n, line in enumerate(md.read_text(encoding="utf-8").splitlines(), 1):
            for target in re.findall(r"\]\(([^)\s]+)\)", line):
                if re.match(r"^[a-z]+://|^mailto:|^#", target):
                    continue
                path = target.split("#", 1)[0]
                if not (md.parent / path).exists():
                    bad.append(f"{md.relative_to(ROOT)}:{n}: {target}")
    assert not bad, "broken links:\n" + "\n".join(bad)


def test_help_texts_speak_of_the_product():
    from stiff.cli import build_parser

    parser = build_parser()
    texts = [parser.format_help()]
    for action in parser._subparsers._group_actions:
        for name, sub in action.choices.items():
            texts.append(sub.format_help())
            for a in sub._actions:
                if hasattr(a, "choices") and isinstance(a.choices, dict):
                    texts += [s.format_help() for s in a.choices.values()]
    pattern = re.compile(r"\bissues? #?\d+|\bthe lead\b", re.I)
    bad = [m.group(0) for t in texts for m in pattern.finditer(t)]
    assert not bad, bad


# ---------------------------------------------------------------- --help examples

# Examples that do not run in a test: each says why.
HELP_NOT_RUN = {
    "stiff demo": "the whole demo; test_cli.test_demo_runs runs it into a temporary folder",
    "stiff study": "a Monte-Carlo study of minutes; test_study.py runs a small one",
    "--task machining.csv": "needs the user's own task file (poses and loads of use)",
}
# The order in which the examples build on each other's files (plan.csv, data.csv, fit.json).
HELP_ORDER = ["examples", "robot", "effects", "import", "plan", "simulate", "identify",
              "diagnose", "predict", "compensate", "fmu", "demo", "study"]


def _help_examples():
    from stiff.cli import build_parser

    parser = build_parser()
    subs = next(a for a in parser._subparsers._group_actions).choices
    out = []
    for name in HELP_ORDER:
        if name not in subs:
            continue
        epilog = subs[name].epilog or ""
        lines, cmd = epilog.splitlines(), ""
        for line in lines:
            text = line.strip()
            if not cmd and not (text.startswith("stiff ") or text.startswith("python -c")):
                continue
            cmd += (" " if cmd else "") + text.rstrip("\\").strip()
            if not text.endswith("\\"):
                out.append((name, cmd))
                cmd = ""
    return out


def test_help_examples_run_as_written(tmp_path):
    env = dict(os.environ)
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    env["MPLBACKEND"] = "Agg"
    (tmp_path / "examples").symlink_to(ROOT / "examples")  # as in a clean checkout
    ran = 0
    for name, cmd in _help_examples():
        if any(key in cmd for key in HELP_NOT_RUN):
            continue
        p = subprocess.run(["bash", "-e", "-c", cmd], cwd=tmp_path, env=env, capture_output=True,
                           text=True)
        assert p.returncode == 0, (f"stiff {name} --help example failed ({p.returncode}):\n{cmd}\n"
                                   f"--- stderr\n{p.stderr[-3000:]}")
        ran += 1
    assert ran >= 20
