"""Output folders that are only ever cleared of what the tool itself wrote.

A command that writes results into a folder (``fpr calibrate --out DIR``, the report of ``fpr demo``)
keeps a listing of what it wrote, :data:`LISTING_NAME`, inside that folder: the tool, when it ran,
and per file its path relative to the folder, its size and its SHA-256. The next run into the same
folder reads it:

* a folder holding anything the listing does not account for (a user's file, a listed file the user
  has since edited or replaced, a subfolder, a link) is refused, and the message names what is there;
* a folder holding only an earlier run's files is refused unless ``overwrite`` is given, and then
  exactly the listed files are removed (and the folders the tool created, when empty), nothing else;
* the run's input files are never removed: a folder where one would be is refused, naming it.

The listing is written when the folder is prepared and again each time a path is recorded, *before*
the file is written; the sizes and hashes are added when the run closes the folder (also when it
ends with an exception). A run killed outright (SIGKILL, power loss) leaves the recorded paths
without hashes: the next ``--overwrite`` removes them as the tool's own, since the tool claimed each
name before it created the file.

A tool that writes a few files of fixed names into a folder that also holds other things (the
summary of a Monte Carlo run folder) uses :func:`prepare_files` instead: a listing of its own
name (e.g. ``.fpr-summary.json``) records those files, and a file of one of those names is
replaced only when that listing says the tool wrote it and it is unchanged since; anything else in
the folder is never looked at.

Pure standard library; no file in the folder is ever executed, unpickled or followed out of the
folder through a link.

Examples
--------
>>> folder = prepare_output("results", overwrite=args.overwrite, tool="fpr calibrate",
...                         protect=input_paths(problem))          # doctest: +SKIP
>>> with folder:                                                    # doctest: +SKIP
...     frame.to_csv(folder.record(folder.path / "table.csv"))
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

#: The listing's file name inside an output folder.
LISTING_NAME = ".fpr-written.json"
#: The temporary file the listing is written through (an atomic replace), also the tool's own.
_LISTING_TMP = LISTING_NAME + ".tmp"
#: The listing's format name and version (a listing of another format is not trusted).
LISTING_FORMAT = "fpr-written-files"
LISTING_VERSION = 1
#: Names shown in a refusal before "and N more".
MAX_NAMES_SHOWN = 10

#: A hook a writer calls with each path it is about to write (:meth:`OutputFolder.record`).
Recorder = Callable[[Path], object]


class OutputFolderError(ValueError):
    """An output folder cannot be used as asked; the message says what is there and what to do."""


@dataclass
class _Listing:
    tool: str = ""
    started_utc: str = ""
    finished_utc: str | None = None
    #: relative POSIX path -> (size, sha256), both None while the file is being written
    files: dict[str, tuple[int | None, str | None]] = field(default_factory=dict)
    #: folders the tool created inside the output folder (relative POSIX paths)
    dirs: list[str] = field(default_factory=list)

    def to_json(self) -> str:
        return json.dumps({
            "format": LISTING_FORMAT, "version": LISTING_VERSION, "tool": self.tool,
            "started_utc": self.started_utc, "finished_utc": self.finished_utc,
            "note": "files this tool wrote here; `--overwrite` removes exactly these, nothing else",
            "directories": sorted(self.dirs),
            "files": [{"path": p, "size": s, "sha256": h} for p, (s, h) in sorted(self.files.items())],
        }, indent=1) + "\n"

    @classmethod
    def parse(cls, text: str) -> _Listing:
        """The listing in ``text``; ValueError for anything but a well-formed listing."""
        doc = json.loads(text)
        if not isinstance(doc, dict) or doc.get("format") != LISTING_FORMAT:
            raise ValueError("not a listing of written files")
        if doc.get("version") != LISTING_VERSION:
            raise ValueError(f"listing version {doc.get('version')!r}, this tool reads {LISTING_VERSION}")
        files: dict[str, tuple[int | None, str | None]] = {}
        for e in doc.get("files", []):
            p, s, h = e["path"], e.get("size"), e.get("sha256")
            if not isinstance(p, str) or not _safe_relative(p):
                raise ValueError(f"file entry {p!r} is not a plain path inside the folder")
            hashed = isinstance(s, int) and isinstance(h, str)
            if not (hashed or (s is None and h is None)):
                raise ValueError(f"file entry {p!r}: size and sha256 malformed")
            files[p] = (s, h)
        dirs = doc.get("directories", [])
        if not all(isinstance(d, str) and _safe_relative(d) for d in dirs):
            raise ValueError("a directory entry is not a plain path inside the folder")
        return cls(tool=str(doc.get("tool", "")), started_utc=str(doc.get("started_utc", "")),
                   finished_utc=doc.get("finished_utc"), files=files, dirs=list(dirs))


def _safe_relative(p: str) -> bool:
    parts = p.split("/")
    return bool(p) and not p.startswith("/") and all(s not in ("", ".", "..") for s in parts)


def _now() -> str:
    return datetime.now(UTC).strftime("%Y-%m-%d %H:%M:%S UTC")


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _file_id(p: Path) -> tuple[int, int] | None:
    """(device, inode) of an existing path (a link followed: the input it points at), else None."""
    try:
        st = os.stat(p)
    except OSError:
        return None
    return st.st_dev, st.st_ino


@dataclass
class _Survey:
    """What an existing output folder holds, against its listing."""

    listing: _Listing | None
    listing_problem: str | None  # why a listing file present could not be used
    ours: list[str]              # listed files, unchanged (or still unhashed), relative POSIX paths
    ours_dirs: list[str]         # listed folders present
    foreign: list[str]           # what the tool did not write ("sub/" for a folder)
    changed: list[str]           # listed files edited or replaced since


def _survey(folder: Path) -> _Survey:
    listing, problem = None, None
    lp = folder / LISTING_NAME
    if lp.is_symlink() or (lp.exists() and not lp.is_file()):
        problem = f"{LISTING_NAME} is not a plain file"
    elif lp.exists():
        try:
            listing = _Listing.parse(lp.read_text(encoding="utf-8"))
        except (ValueError, KeyError, TypeError, UnicodeDecodeError) as exc:
            problem = f"{LISTING_NAME} cannot be read ({exc})"
    files = listing.files if listing else {}
    dirs = set(listing.dirs) if listing else set()
    ours, ours_dirs, foreign, changed = [], [], [], []

    def walk(d: Path, prefix: str) -> None:
        with os.scandir(d) as it:
            entries = sorted(it, key=lambda e: e.name)
        for e in entries:
            rel = prefix + e.name
            if not prefix and listing is not None and e.name in (LISTING_NAME, _LISTING_TMP):
                continue
            st = e.stat(follow_symlinks=False)
            if stat.S_ISDIR(st.st_mode):
                if rel in dirs:
                    ours_dirs.append(rel)
                    walk(Path(e.path), rel + "/")
                else:
                    foreign.append(rel + "/")
            elif rel in files:
                size, digest = files[rel]
                if not stat.S_ISREG(st.st_mode):
                    changed.append(f"{rel} (replaced by a link or special file)")
                elif size is not None and (st.st_size != size or _sha256(Path(e.path)) != digest):
                    changed.append(f"{rel} (changed since {listing.tool or 'the tool'} wrote it)")
                elif size is None and not _unhashed_is_ours(listing, st.st_mtime):
                    # an entry without size and hash is a file a killed run had begun to write:
                    # only a run that stopped before it finished leaves one, and only a file
                    # written since that run started can be it
                    changed.append(f"{rel} (listed without size and hash, but not by a run that was "
                                   "stopped while writing it)")
                else:
                    ours.append(rel)
            else:
                foreign.append(rel + ("/" if e.is_dir() else ""))

    walk(folder, "")
    return _Survey(listing, problem, ours, ours_dirs, foreign, changed)


def _unhashed_is_ours(listing: _Listing, mtime_s: float) -> bool:
    """A listed file without size and hash counts as the tool's only if the listing's run never
    finished and the file was modified after that run started (2 s of clock resolution)."""
    if listing.finished_utc is not None:
        return False
    try:
        started = datetime.strptime(listing.started_utc, "%Y-%m-%d %H:%M:%S UTC").replace(tzinfo=UTC)
    except ValueError:
        return False
    return mtime_s >= started.timestamp() - 2.0


def _names(items: list[str]) -> str:
    shown = ", ".join(items[:MAX_NAMES_SHOWN])
    more = len(items) - MAX_NAMES_SHOWN
    return shown + (f" and {more} more" if more > 0 else "")


def _check(out: Path, overwrite: bool, protect: Iterable[str | os.PathLike]) -> _Survey | None:
    """Every refusal of :func:`prepare_output`, without changing anything; the survey of an
    existing folder (None when it does not exist yet)."""
    protect = [Path(p) for p in protect]
    inputs = {i: p for p in protect if (i := _file_id(p)) is not None}
    out_id = _file_id(out)
    if out_id is not None and out_id in inputs:
        raise OutputFolderError(f"{out} is an input of this run ({inputs[out_id]}); results go to a folder "
                                "of their own: choose another --out")
    if out.exists() and not out.is_dir():
        raise OutputFolderError(f"{out} exists and is not a folder; choose another --out")
    if not out.exists():
        return None
    s = _survey(out)

    def is_input(rel: str) -> bool:
        return _file_id(out / rel.rstrip("/")) in inputs

    strangers = [f"{r} (an input of this run)" if is_input(r) else r for r in s.foreign] + s.changed
    if s.listing_problem and not strangers:
        strangers = [f"{LISTING_NAME} ({s.listing_problem})"]
    if strangers:
        what = "files fpr did not write" if s.listing is None else "files that are not the results of " \
            f"an earlier run of {s.listing.tool or 'fpr'}"
        extra = f"; {s.listing_problem}" if s.listing_problem else ""
        raise OutputFolderError(
            f"{out} holds {what}: {_names(strangers)}{extra}. fpr only ever removes what it wrote "
            f"itself: choose another --out (an empty or new folder), or move those files out of {out}")
    if s.listing is None:
        return s  # an empty folder
    when = s.listing.finished_utc or s.listing.started_utc or "at an unknown time"
    stopped = "" if s.listing.finished_utc else "; that run stopped before it finished"
    if not overwrite:
        raise OutputFolderError(
            f"{out} holds the results of an earlier run (written {when} by {s.listing.tool or 'fpr'}"
            f"{stopped}); pass --overwrite to replace them or choose another --out")
    inputs = [r for r in s.ours if is_input(r)]
    if inputs:
        raise OutputFolderError(
            f"{out}: {_names(inputs)} is an input of this run and was written by an earlier run; "
            "--overwrite would remove it: copy it elsewhere and point the problem at the copy, or "
            "choose another --out")
    return s


def check_output(out_dir: str | os.PathLike, *, overwrite: bool,
                 protect: Iterable[str | os.PathLike] = ()) -> None:
    """Raise the :class:`OutputFolderError` that :func:`prepare_output` would, changing nothing.

    For a command that learns much later that it will write there (``fpr demo`` flies a campaign
    first): it stops at once instead of after the work.
    """
    _check(Path(out_dir), overwrite, list(protect))


def prepare_output(out_dir: str | os.PathLike, *, overwrite: bool, tool: str,
                   protect: Iterable[str | os.PathLike] = ()) -> OutputFolder:
    """Make ``out_dir`` ready for a run's results and return it, listing from now on what is written.

    Parameters
    ----------
    out_dir : the output folder; created (with its parents) when missing.
    overwrite : remove an earlier run's files (exactly those its listing names, unchanged).
    tool : who writes, e.g. ``"fpr calibrate"``; said in later refusals.
    protect : the run's input files (and folders, e.g. a dataset): never removed, never the output.

    Raises
    ------
    OutputFolderError
        ``out_dir`` is a file or an input of the run; it holds anything the tool did not write
        (listed by name); it holds an earlier run's results and ``overwrite`` is false; or an input
        of the run is among the earlier run's files.
    """
    out = Path(out_dir)
    protect = list(protect)
    survey = _check(out, overwrite, protect)
    if survey is None:
        out.mkdir(parents=True)
    elif survey.listing is not None:
        # only the tool's own files are here (checked above): remove exactly those, never following
        # a link (a listed name that became a link was refused as changed)
        for rel in survey.ours:
            (out / rel).unlink(missing_ok=True)
        for rel in sorted(survey.ours_dirs, key=lambda r: r.count("/"), reverse=True):
            try:
                (out / rel).rmdir()
            except OSError:
                pass  # not empty: something the tool did not write is inside; it stays
        (out / _LISTING_TMP).unlink(missing_ok=True)
        (out / LISTING_NAME).unlink(missing_ok=True)
    return OutputFolder(out, tool, created=survey is None)


class OutputFolder:
    """An output folder being written; every file the run writes is :meth:`record`-ed in its listing.

    Use it as a context manager (or call :meth:`close`): at the end the listing gets each file's size
    and hash, so that a file later edited under the same name is no longer taken for the tool's.
    """

    def __init__(self, path: Path, tool: str, created: bool = False,
                 listing_name: str = LISTING_NAME) -> None:
        self.path = Path(path)
        self.tool = tool
        self._created = created  # the run made the folder: removed again if it writes nothing
        self.listing_name = listing_name  # another name for a set of files in a shared folder
        self._listing = _Listing(tool=tool, started_utc=_now())
        self._closed = False
        self._save()

    def record(self, path: str | os.PathLike) -> Path:
        """Claim ``path`` (inside the folder) as written by this run; call it before writing.

        Returns the path, so that ``frame.to_csv(folder.record(folder.path / "x.csv"))`` reads on.
        Missing parent folders inside the output folder are created and listed.
        """
        p = Path(path)
        rel = os.path.relpath(os.path.abspath(p), os.path.abspath(self.path)).replace(os.sep, "/")
        if not _safe_relative(rel):
            raise OutputFolderError(f"{p} is not inside the output folder {self.path}")
        if rel in (LISTING_NAME, _LISTING_TMP, self.listing_name, self.listing_name + ".tmp"):
            raise OutputFolderError(f"{p}: {rel} is the output folder's own listing")
        if self._closed:
            raise RuntimeError(f"{self.path}: the output folder is closed; nothing more can be recorded")
        parts = rel.split("/")
        for i in range(1, len(parts)):
            sub = "/".join(parts[:i])
            d = self.path / sub
            if not d.exists():
                d.mkdir()
                self._listing.dirs.append(sub)
        if rel not in self._listing.files:
            self._listing.files[rel] = (None, None)
            self._save()
        return p

    @property
    def recorded(self) -> list[Path]:
        """The paths recorded so far."""
        return [self.path / r for r in sorted(self._listing.files)]

    def close(self, finished: bool = True) -> None:
        """Write the final listing: size and SHA-256 of every recorded file that exists.

        ``finished`` False (the run ended with an exception) leaves the run marked as stopped.
        """
        if self._closed:
            return
        files = {}
        for rel in self._listing.files:
            p = self.path / rel
            try:
                st = p.lstat()
            except FileNotFoundError:
                continue  # claimed, never written
            if stat.S_ISREG(st.st_mode):
                files[rel] = (st.st_size, _sha256(p))
        self._listing.files = files
        self._closed = True
        if not files and not self._listing.dirs:
            # nothing written (the run stopped first): no listing, so the next run needs no
            # --overwrite; a folder this run created goes too
            (self.path / self.listing_name).unlink(missing_ok=True)
            if self._created:
                try:
                    self.path.rmdir()
                except OSError:
                    pass  # something else appeared in it meanwhile: it stays
            return
        if finished:
            self._listing.finished_utc = _now()
        self._save()

    def __enter__(self) -> OutputFolder:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(finished=exc_type is None)

    def _save(self) -> None:
        # through a temporary file and an atomic rename: a crash never leaves half a listing
        tmp = self.path / (self.listing_name + ".tmp")
        tmp.write_text(self._listing.to_json(), encoding="utf-8")
        os.replace(tmp, self.path / self.listing_name)


def _check_files(folder: Path, names: Iterable[str], listing_name: str, tool: str,
                 advice: str) -> list[str]:
    """Every refusal of :func:`prepare_files`, changing nothing; the names (of ``names``) present
    that the tool wrote there and that are unchanged since."""
    names = list(dict.fromkeys(names))
    for n in (*names, listing_name):
        if "/" in n or not _safe_relative(n):
            raise ValueError(f"{n!r}: a file name inside {folder} is expected, not a path")
    if folder.exists() and not folder.is_dir():
        raise OutputFolderError(f"{folder} exists and is not a folder; choose another folder")
    if not folder.exists():
        return []
    listed: dict[str, tuple[int | None, str | None]] = {}
    strangers: list[str] = []
    lp = folder / listing_name
    if lp.is_symlink() or (lp.exists() and not lp.is_file()):
        strangers.append(f"{lp} (not a plain file)")
    elif lp.exists():
        try:
            listed = _Listing.parse(lp.read_text(encoding="utf-8")).files
        except (ValueError, KeyError, TypeError, UnicodeDecodeError) as exc:
            strangers.append(f"{lp} (not a listing fpr wrote: {exc})")
    ours = []
    for name in names:
        p = folder / name
        try:
            st = p.lstat()
        except FileNotFoundError:
            continue
        if name not in listed:
            strangers.append(f"{p} ({tool} did not write it)")
        elif not stat.S_ISREG(st.st_mode):
            strangers.append(f"{p} (replaced by a link, folder or special file)")
        else:
            size, digest = listed[name]
            # unhashed: claimed by a run that was killed before it closed; the name was the tool's
            if size is not None and (st.st_size != size or _sha256(p) != digest):
                strangers.append(f"{p} (changed since {tool} wrote it)")
            else:
                ours.append(name)
    if strangers:
        one = len(strangers) == 1
        # a folder an older version wrote into, before it kept the listing, has none at all
        older = "" if lp.exists() or lp.is_symlink() else \
            f" ({folder} holds no {listing_name}: even a file an older fpr wrote there is not recognised)"
        raise OutputFolderError(
            f"{_names(strangers)}: {tool} replaces only files it wrote itself, unchanged, and "
            f"{'this one is' if one else 'these are'} not{older}. Move {'it' if one else 'them'} out "
            f"of {folder} (or rename {'it' if one else 'them'})" + (f", {advice}" if advice else ""))
    return ours


def check_files(folder: str | os.PathLike, names: Iterable[str], *, listing_name: str, tool: str,
                advice: str = "") -> None:
    """Raise the :class:`OutputFolderError` that :func:`prepare_files` would, changing nothing.

    For a command that writes the files only at the end of a long run: it stops at once instead.
    """
    _check_files(Path(folder), names, listing_name, tool, advice)


def prepare_files(folder: str | os.PathLike, names: Iterable[str], *, listing_name: str, tool: str,
                  advice: str = "") -> OutputFolder:
    """Make ready to (re)write the files ``names`` in ``folder``, a folder that may hold anything else.

    The tool's earlier files of those names are removed — only those that the listing
    ``listing_name`` in ``folder`` records, unchanged since (size and SHA-256) — and the returned
    :class:`OutputFolder` lists the files written from now on in that listing (``record`` each path
    before writing it; close it, or use it as a context manager). Nothing else in ``folder`` is
    looked at, listed or removed; it is created (with its parents) when missing.

    Parameters
    ----------
    folder : where the files go.
    names : the file names (no paths) the tool writes there, e.g. ``("summary.txt", "summary.png")``.
    listing_name : the listing's file name in ``folder``, one per tool and set of files
        (e.g. ``".fpr-summary.json"``; not :data:`LISTING_NAME`, which lists a whole output folder).
    tool : who writes, e.g. ``"fpr montecarlo-summary"``; said in refusals.
    advice : appended to a refusal: what else the user can do (e.g. ``"or choose --summary-dir"``).

    Raises
    ------
    OutputFolderError
        ``folder`` is a file; or a file of one of ``names`` exists that the listing does not record,
        that changed since, or that is a link or folder (each named, with the path); or the listing
        itself is not one fpr wrote.
    """
    folder = Path(folder)
    ours = _check_files(folder, names, listing_name, tool, advice)
    created = not folder.exists()
    folder.mkdir(parents=True, exist_ok=True)
    for name in ours:  # the tool's own, unchanged (checked above); never a link
        (folder / name).unlink(missing_ok=True)
    return OutputFolder(folder, tool, created=created, listing_name=listing_name)


def input_paths(problem) -> list[Path]:
    """The files (and dataset folders) an estimation problem was read from, to :func:`prepare_output`'s
    ``protect``: the problem file or dataset (``problem.source``), each maneuver's data file
    (``meta["file"]``, relative to ``meta["dataset"]`` for a dataset) and a dataset's manifest."""
    paths: list[Path] = []
    if getattr(problem, "source", ""):
        paths.append(Path(problem.source))
    for m in getattr(problem, "maneuvers", ()):
        meta = getattr(m, "meta", {}) or {}
        ds = meta.get("dataset")
        if ds:
            paths += [Path(ds), Path(ds) / "manifest.json"]
        f = meta.get("file")
        if f:
            paths.append(Path(ds) / f if ds and not Path(f).is_absolute() else Path(f))
    return list(dict.fromkeys(paths))
