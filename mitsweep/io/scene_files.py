"""The files a Mitsuba XML scene loads, found without Mitsuba, and their SHA-256.

:func:`scene_files` reads a scene's XML (a lenient scan of its tags, before Mitsuba's
parser ever sees it) and lists every file loading it opens: the file itself, its ``<include>``\\ s
(recursively, at most :data:`MAX_INCLUDE_DEPTH` deep, Mitsuba's own limit), every
``filename`` string property (bitmap textures, meshes, environment maps, grid volumes,
measured BSDFs, ...) and every ``<spectrum filename=...>``. Each is checked to be a
regular file (:func:`mitsweep.resources.require_regular_file`), so Mitsuba's parser is
never handed a named pipe or a device, on which it would block for ever.

File names resolve as Mitsuba 3's parser and :class:`mitsuba.FileResolver` resolve them
(``src/core/parser.cpp``): ``$name`` parameters take the ``<default>`` values (the first
definition wins); a relative name is the first that exists of the resolver's folders,
else the name itself (relative to the working directory). The resolver of the
top-level file holds its ``<path>`` folders (latest first), the scene's folder and the
working directory; an ``<include>`` and its ``<spectrum filename>``\\ s resolve against
the including file's folder first, then the resolver it was parsed under (its
``<path>``\\ s stay in it); plugin ``filename`` properties are resolved when the scene
is instantiated, against the top-level resolver, wherever they were written.

:func:`scene_digests` turns that list into ``{name: SHA-256}``, the content identity of
a scene: names are relative to the scene's folder (absolute for files outside it), so
the same scene reached through another spelling of its path has the same digests.
"""

from __future__ import annotations

import errno
import hashlib
import os
import re
from pathlib import Path
from xml.sax.saxutils import unescape

from ..resources import require_regular_file

__all__ = ["SceneFileError", "MAX_INCLUDE_DEPTH", "scene_files", "scene_digests",
           "changed_files", "file_sha256"]

#: Deepest ``<include>`` nesting: Mitsuba's ``ParserConfig.max_include_depth``.
MAX_INCLUDE_DEPTH = 15


class SceneFileError(ValueError):
    """A scene's XML cannot be read, or its includes nest too deep or in a cycle: one
    line naming the file."""


def file_sha256(path: str | os.PathLike) -> str:
    """The SHA-256 of a file's bytes, read in 1 MiB chunks.

    Parameters
    ----------
    path : str or os.PathLike
        The file.

    Returns
    -------
    str
        The digest, 64 lowercase hexadecimal digits.
    """
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _resolve(name: str, folders: list[Path]) -> Path:
    """``FileResolver::resolve``: an absolute name as it is, else the first folder where
    it exists (``fs::exists``: any kind of file), else the name itself."""
    p = Path(name)
    if not p.is_absolute():
        for base in folders:
            if (base / p).exists():
                return base / p
    return p


#: What pugixml skips: comments (which may hold ``--``, which Python's XML parser
#: refuses and pugixml does not), CDATA, processing instructions and the doctype.
_SKIPPED = re.compile(r"<!--.*?-->|<!\[CDATA\[.*?\]\]>|<\?.*?\?>|<!DOCTYPE[^>]*>", re.S)
_TAG = re.compile(r"<([A-Za-z_][\w.:-]*)((?:\s+[^\s=/>]+\s*=\s*(?:\"[^\"]*\"|'[^']*'))*)\s*/?>")
_ATTR = re.compile(r"([^\s=/>]+)\s*=\s*(?:\"([^\"]*)\"|'([^']*)')")
_ENTITIES = {"&quot;": '"', "&apos;": "'"}


def _tags(text: str):
    """``(tag, attributes)`` of every start tag of an XML text, in document order.

    A tokenizer, not a validating parser: Mitsuba's pugixml accepts what Python's
    parser refuses (``--`` in a comment, undeclared entities), and a file pugixml
    refuses is never read further, so a lenient scan finds at least what the parser
    would open. Values are unescaped as XML.
    """
    for m in _TAG.finditer(_SKIPPED.sub("", text)):
        attr = {a.group(1): unescape(a.group(2) if a.group(2) is not None else a.group(3),
                                     _ENTITIES)
                for a in _ATTR.finditer(m.group(2))}
        yield m.group(1), attr


def _substitute(value: str, params: dict[str, str]) -> str:
    """``$name`` → its ``<default>`` value, longest names first, ``\\$`` left alone
    (an undefined one stays: Mitsuba refuses the file itself)."""
    if "$" not in value:
        return value
    for key in sorted(params, key=len, reverse=True):
        out, pos, token = [], 0, "$" + key
        while (k := value.find(token, pos)) >= 0:
            if k > 0 and value[k - 1] == "\\":
                out.append(value[pos:k + len(token)])
            else:
                out.append(value[pos:k] + params[key])
            pos = k + len(token)
        value = "".join(out) + value[pos:]
    return value


class _Scan:
    def __init__(self, top: Path) -> None:
        self.found: dict[Path, None] = {}        # in the order Mitsuba meets them
        self.params: dict[str, str] = {}
        self.plugin_files: list[tuple[str, Path]] = []  # resolved once it is all parsed
        self.top_resolver = [top.parent, Path.cwd()]

    def add(self, path: Path, what: str) -> None:
        require_regular_file(path, what)
        if path.exists():   # a missing file: Mitsuba's own message names it
            self.found.setdefault(path, None)

    def parse(self, path: Path, resolver: list[Path], chain: tuple[Path, ...]) -> None:
        if len(chain) >= MAX_INCLUDE_DEPTH:  # the top file is depth 0
            raise SceneFileError(f"{chain[0]}: <include>s nested deeper than "
                                 f"{MAX_INCLUDE_DEPTH} levels (Mitsuba's limit), at {path}")
        if not path.exists():
            if chain:   # a missing include: Mitsuba's own message names it
                return
            raise FileNotFoundError(errno.ENOENT, "no such scene file", str(path))
        key = path.resolve()
        if key in {p.resolve() for p in chain}:
            raise SceneFileError(f"{chain[0]}: <include> cycle: {path} includes itself")
        self.add(path, "scene file" if not chain else f"file included by {chain[-1]}")
        try:
            text = path.read_bytes().decode("utf-8", errors="replace")
        except OSError as exc:
            raise SceneFileError(f"{path}: cannot read ({exc.strerror or exc})") from None
        for tag, attr in _tags(text):
            self.tag(tag, {k: _substitute(v, self.params) for k, v in attr.items()}, path,
                     resolver, (*chain, path))

    def tag(self, tag: str, attr: dict[str, str], path: Path, resolver: list[Path],
            chain: tuple[Path, ...]) -> None:
        if tag == "default" and "name" in attr:
            self.params.setdefault(attr["name"], attr.get("value", ""))
        elif tag == "path" and "value" in attr:
            folder = Path(attr["value"])
            if not folder.is_absolute():
                folder = path.parent / folder if (path.parent / folder).exists() \
                    else _resolve(attr["value"], resolver)
            resolver.insert(0, folder)   # top level: the instantiation's resolver too
        elif tag == "include" and "filename" in attr:
            inner = [path.parent, *resolver]
            self.parse(_resolve(attr["filename"], inner), inner, chain)
        elif tag == "spectrum" and "filename" in attr and "type" not in attr:
            self.add(_resolve(attr["filename"], resolver), f"spectrum file of {path}")
        elif tag == "string" and attr.get("name") == "filename" and "value" in attr:
            self.plugin_files.append((attr["value"], path))


def scene_files(path: str | os.PathLike) -> list[Path]:
    """Every file Mitsuba opens to load the XML scene ``path``, each checked regular.

    See the module docstring for what is found and how names resolve. Files that do not
    exist are left out (Mitsuba's own message names them); each file appears once, in
    the order the parser meets it (the scene first).

    Parameters
    ----------
    path : str or os.PathLike
        The top-level XML scene file.

    Returns
    -------
    list of Path
        The files, as resolved (not made absolute).

    Raises
    ------
    FileNotFoundError
        ``path`` itself does not exist.
    mitsweep.resources.FileTypeError
        One of them is a named pipe, device, socket or directory (named, with the file
        that references it).
    SceneFileError
        ``<include>``\\ s nest deeper than :data:`MAX_INCLUDE_DEPTH` or in a cycle. (A
        file that is not well-formed XML is scanned all the same, leniently: Mitsuba's
        parser reports it.)
    """
    top = Path(path)
    scan = _Scan(top)
    scan.parse(top, scan.top_resolver, ())
    for name, where in scan.plugin_files:
        scan.add(_resolve(name, scan.top_resolver), f"file named in {where}")
    return list(scan.found)


def _name(p: Path, folder: Path) -> str:
    q = p.resolve()
    return q.relative_to(folder).as_posix() if q.is_relative_to(folder) else q.as_posix()


def scene_digests(path: str | os.PathLike) -> dict[str, str]:
    """``{name: SHA-256}`` of every file of :func:`scene_files`, sorted by name; names
    are relative to the scene's folder (symlinks resolved), or absolute outside it.

    Parameters
    ----------
    path : str or os.PathLike
        The top-level XML scene file.
    """
    files = scene_files(path)
    folder = Path(path).resolve().parent
    return dict(sorted((_name(p, folder), file_sha256(p)) for p in files))


def changed_files(recorded: dict[str, str], path: str | os.PathLike) -> list[str]:
    """Names whose content differs between ``recorded`` (:func:`scene_digests` of an
    earlier time) and the scene now: changed, gone or new, sorted.

    Parameters
    ----------
    recorded : dict of str to str
        ``{name: SHA-256}`` as :func:`scene_digests` gave it earlier.
    path : str or os.PathLike
        The top-level XML scene file, digested again now.
    """
    now = scene_digests(path)
    return sorted(n for n in set(recorded) | set(now) if recorded.get(n) != now.get(n))
