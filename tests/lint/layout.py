#!/usr/bin/env python3
"""Checks that the tree shows the architecture docs/ARCHITECTURE.md describes.

1. Every library folder of the folder table exists, is made by vts_library() and vice versa.
2. No file includes another folder's src/ (or climbs out of its folder with "../").
3. Includes follow the dependency graph: a library includes only its own headers and those of
   the libraries it may depend on.
4. Third-party libraries stay where they belong: no GL in render_core, server, client;
   no OpenImageIO in server, client, render_core, renderer; no Beast outside the server; the
   bc1 encoder (libsquish, stb_dxt) in the builder only.
5. cli/ is glue: no file over 250 lines, no function over 60 lines.

Usage: layout.py [REPO_ROOT]. Prints every violation; exits 1 if there is any.
"""
import pathlib
import re
import sys

# folder -> (include name under vts/, libraries whose headers it may include)
LIBRARIES = {
    "base": ("base", set()),
    "protocol": ("protocol", {"base"}),
    "archive": ("archive", {"base", "protocol"}),
    "store": ("store", {"base", "protocol", "archive"}),
    "imaging": ("imaging", {"base", "protocol"}),
    "builder": ("builder", {"base", "protocol", "archive", "imaging"}),
    "server": ("server", {"base", "protocol", "archive", "store", "imaging"}),
    "client": ("client", {"base", "protocol", "archive", "store", "imaging"}),
    "renderer/core": ("renderer", {"base", "protocol", "archive", "imaging"}),
    "renderer/gl": ("renderer", {"base", "protocol", "archive", "imaging", "client"}),
    "plot": ("plot", {"base", "protocol"}),
    "loadtest": ("loadtest", {"base", "protocol", "archive", "imaging", "client", "plot", "renderer"}),
    "accuracy": ("accuracy", {"base", "protocol", "archive", "imaging", "builder", "client", "plot",
                              "renderer"}),
}
# The bc1 encoder (libsquish, stb_dxt) is the builder's: whatever only reads tiles never links it.
_NO_ENCODER = ["squish.h", "stb/stb_dxt.h"]
_NO_HEAVY = ["GLFW/", "epoxy/", "OpenImageIO/", "gdal", "boost/", "curl/", "sqlite3.h"] + _NO_ENCODER
FORBIDDEN = {  # folder -> include prefixes it must not use
    "base": _NO_HEAVY + ["png.h", "webp/", "turbojpeg.h", "zstd.h"],
    "protocol": _NO_HEAVY + ["png.h", "webp/", "turbojpeg.h"],
    "archive": _NO_HEAVY + ["png.h", "webp/", "turbojpeg.h"],
    # The store reads remote archives: libcurl (as the client does) and Expat, for S3's XML.
    "store": ["GLFW/", "epoxy/", "OpenImageIO/", "gdal", "boost/", "sqlite3.h", "png.h", "webp/",
              "turbojpeg.h"] + _NO_ENCODER,
    "imaging": _NO_HEAVY,
    # SQLite only as the MBTiles container `vts export --format mbtiles` writes
    "builder": ["GLFW/", "epoxy/", "boost/", "curl/"],
    "server": ["GLFW/", "epoxy/", "OpenImageIO/", "gdal", "curl/", "sqlite3.h"] + _NO_ENCODER,
    "client": ["GLFW/", "epoxy/", "OpenImageIO/", "gdal", "boost/"] + _NO_ENCODER,
    "renderer/core": _NO_HEAVY,
    "renderer/gl": ["OpenImageIO/", "gdal", "boost/", "curl/", "sqlite3.h"] + _NO_ENCODER,
    "plot": _NO_HEAVY,
    "loadtest": ["GLFW/", "epoxy/", "OpenImageIO/", "gdal", "boost/", "sqlite3.h"] + _NO_ENCODER,
}
INCLUDE = re.compile(r'^\s*#\s*include\s*[<"]([^>"]+)[>"]', re.M)


def check(ROOT):
    """Every violation in the tree at ROOT, as lines."""
    problems = []

    def sources(folder):
        return sorted(p for p in (ROOT / folder).rglob("*") if p.suffix in (".cpp", ".hpp", ".h"))




    # 1. The folder table and the tree agree.
    arch = (ROOT / "docs/ARCHITECTURE.md").read_text()
    table = set(re.findall(r"^\| `([a-z/]+)/` \| `vts::", arch, re.M))
    made = {str(p.parent.relative_to(ROOT)) for p in ROOT.rglob("CMakeLists.txt")
            if "vts_library(" in p.read_text() and "tests" not in p.parts and "build" not in p.parts[0]}
    made.discard("cmake")
    for folder in sorted(table ^ made):
        where = "docs/ARCHITECTURE.md's folder table" if folder in made else "the tree (vts_library)"
        problems.append(f"library folder {folder}/ is missing from {where}")
    for folder in sorted(made - set(LIBRARIES)):
        problems.append(f"library folder {folder}/ is not known to tests/lint/layout.py")

    # 2-4. Includes.
    every = [p for p in ROOT.rglob("*") if p.suffix in (".cpp", ".hpp", ".h")
             and not any(part.startswith(("build", ".")) or part == "node_modules" for part in
                         p.relative_to(ROOT).parts)]
    for path in every:
        rel = path.relative_to(ROOT)
        for inc in INCLUDE.findall(path.read_text(errors="replace")):
            if inc.startswith("../") or "/src/" in inc or inc.startswith("src/"):  # noqa: E501
                problems.append(f"{rel}: includes \"{inc}\" (another folder's private files)")
    for folder, (name, allowed) in LIBRARIES.items():
        for path in sources(folder):
            rel = path.relative_to(ROOT)
            for inc in INCLUDE.findall(path.read_text(errors="replace")):
                m = re.match(r"vts/([a-z_]+)/", inc)
                if m and m.group(1) != name and m.group(1) not in allowed:
                    problems.append(f"{rel}: {folder}/ may not include {inc}")
                if folder == "renderer/core" and inc.startswith("vts/renderer/"):
                    header = ROOT / "renderer/core/include" / inc
                    if not header.exists():
                        problems.append(f"{rel}: the CPU renderer includes the GL side's {inc}")
                for bad in FORBIDDEN.get(folder, []):
                    if inc.startswith(bad):
                        problems.append(f"{rel}: {folder}/ may not use {inc}")

    # 5. cli/ is glue.
    FUNC = re.compile(r"^[A-Za-z_][\w:<>,*& ]*\([^;]*$")
    for path in sources("cli"):
        rel = path.relative_to(ROOT)
        lines = path.read_text().splitlines()
        if len(lines) > 250:
            problems.append(f"{rel}: {len(lines)} lines (cli/ files stay under 250)")
        depth, start, name = 0, None, ""
        for i, line in enumerate(lines):
            code = re.sub(r'"(\\.|[^"\\])*"', '""', line.split("//")[0])
            code = re.sub(r"'(\\.|[^'\\])'", "''", code)
            if re.match(r"\s*(namespace\b.*\{|\}\s*$)", code) and start is None and depth == 0:
                continue  # namespace braces do not nest functions
            if depth == 0 and start is None and FUNC.match(code) and not code.startswith(
                    ("namespace", "struct", "class", "enum", "using", "return", "#")):
                name, start = code.strip(), i
            opened, closed = code.count("{"), code.count("}")
            depth += opened - closed
            if start is not None and depth == 0 and (opened or closed) and "}" in code:
                length = i - start + 1
                if length > 60:
                    problems.append(f"{rel}:{start + 1}: {name[:60]} is {length} lines (at most 60)")
                start = None
            elif start is not None and depth == 0 and code.rstrip().endswith(";"):
                start = None  # a declaration

    return problems, len(every)


def self_test():
    """The check finds what it is meant to find: a tree with one violation of each kind."""
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        root = pathlib.Path(tmp)
        files = {
            "docs/ARCHITECTURE.md": "| `protocol/` | `vts::protocol` | x | |\n| `ghost/` | `vts::ghost` | x | |\n",
            "protocol/CMakeLists.txt": "vts_library(protocol)\n",
            "protocol/src/codec.cpp": "#include <squish.h>\n",
            "server/CMakeLists.txt": "vts_library(server PUBLIC vts::protocol)\n",
            "server/src/a.cpp": '#include "../../protocol/src/b.hpp"\n#include "vts/client/c.hpp"\n'
                                "#include <GLFW/glfw3.h>\n",
            "cli/src/cmd.cpp": "namespace vts {\nint run() {\n" + "  f();\n" * 60 + "}\n}\n" +
                               "// pad\n" * 250,
        }
        for name, text in files.items():
            (root / name).parent.mkdir(parents=True, exist_ok=True)
            (root / name).write_text(text)
        problems, _ = check(root)
        want = ["ghost/ is missing from the tree", "server/ is missing from docs",
                'includes "../../protocol/src/b.hpp"', "server/ may not include vts/client/c.hpp",
                "server/ may not use GLFW/glfw3.h", "protocol/ may not use squish.h",
                "cmd.cpp: 314 lines", "is 62 lines (at most 60)"]
        missed = [w for w in want if not any(w in p for p in problems)]
        for w in missed:
            print("layout self-test: not reported:", w)
        return not missed


if __name__ == "__main__":
    if not self_test():
        sys.exit(2)
    problems, count = check(pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else pathlib.Path(__file__).parents[2]))
    for p in problems:
        print("layout:", p)
    print(f"layout: {len(problems)} problem(s) in {count} files")
    sys.exit(1 if problems else 0)
