"""Results storage: one SQLite file, written only by the coordinating process.

Part of :mod:`auvmpc.experiments.campaign` (docs/campaigns.md).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import sqlite3
from collections.abc import Iterator, Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from auvmpc import __version__
from auvmpc.errors import ConfigError, format_validation_error
from auvmpc.experiments.campaign.spec import (
    LOCK_FILE,
    RESULTS_FILE,
    Campaign,
    CampaignSpec,
    _canonical_json,
    _with_implicit_overrides,
    expand_controller,
)
from auvmpc.experiments.outputs import cannot_write, output_errors

_SCHEMA = """
CREATE TABLE IF NOT EXISTS campaign (
    id INTEGER PRIMARY KEY CHECK (id = 0),
    hash TEXT NOT NULL,
    name TEXT NOT NULL,
    spec TEXT NOT NULL,
    source TEXT NOT NULL,
    base_source TEXT NOT NULL,
    base_data TEXT NOT NULL,
    base_dir TEXT NOT NULL,
    parameter_columns TEXT NOT NULL,
    metric_columns TEXT NOT NULL DEFAULT '[]',
    created_utc TEXT NOT NULL,
    auvmpc_version TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS runs (
    "index" INTEGER PRIMARY KEY,
    seed INTEGER NOT NULL,
    status TEXT NOT NULL CHECK (status IN ('ok', 'failed')),
    error TEXT,
    traceback TEXT,
    parameters TEXT NOT NULL,
    metrics TEXT NOT NULL,
    wall_s REAL,
    worker_deaths INTEGER NOT NULL DEFAULT 0,
    worker TEXT,
    finished_utc TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS sessions (
    started_utc TEXT NOT NULL,
    wall_s REAL NOT NULL,
    new_runs INTEGER NOT NULL,
    provenance TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS worker_deaths (
    "index" INTEGER PRIMARY KEY,
    deaths INTEGER NOT NULL
);
"""


def _connect(path: Path, read_only: bool = False) -> sqlite3.Connection:
    if read_only:
        connection = sqlite3.connect(_read_only_uri(path), uri=True, isolation_level=None)
    else:
        connection = sqlite3.connect(path, isolation_level=None)
        connection.execute("PRAGMA journal_mode=WAL")
        # FULL: a committed run survives a power cut too, not only a killed process.
        connection.execute("PRAGMA synchronous=FULL")
    connection.execute("PRAGMA busy_timeout=10000")
    return connection


def _read_only_uri(path: Path) -> str:
    """The store opened to read. In a folder nobody can write (a read-only mount), SQLite
    cannot create the write-ahead log's index (``-shm``) a reader needs: there the file is
    read as immutable (no locks, no index), which is safe when no write-ahead log holds rows
    beyond it, as after every finished or resumed campaign."""
    uri = f"{path.resolve().as_uri()}?mode=ro"
    wal = path.with_name(path.name + "-wal")
    shm = path.with_name(path.name + "-shm")
    frozen = not os.access(path.parent, os.W_OK) and not shm.exists()
    if frozen and (not wal.exists() or wal.stat().st_size == 0):
        uri += "&immutable=1"
    return uri


@contextlib.contextmanager
def _reading(out_dir: Path) -> Iterator[sqlite3.Connection]:
    """The results of a campaign folder opened to read. A file SQLite cannot read (not a
    database, cut short, a table missing) or a stored row that does not parse is one line
    naming it: damaged, or not a campaign's results."""
    path = _results_path(out_dir)
    try:
        with contextlib.closing(_connect(path, read_only=True)) as db:
            yield db
    except (sqlite3.Error, json.JSONDecodeError) as error:
        raise _unreadable(path, str(error)) from None
    except ValidationError as error:
        raise _unreadable(path, str(format_validation_error(error, "campaign"))) from None


def _unreadable(path: Path, problem: str, field: str = "DIR") -> ConfigError:
    return ConfigError(
        field, str(path), f"{path.name} cannot be read ({problem}): it is damaged or not a "
        "campaign's results",
    )  # fmt: skip


# SQLite's primary result codes for a file the system does not let it write: PERM,
# READONLY, IOERR (a full disk often shows as one), FULL, CANTOPEN.
_STORAGE_REFUSED = frozenset({3, 8, 10, 13, 14})


@contextlib.contextmanager
def _storage_errors(path: Path) -> Iterator[None]:
    """The store's write refused by the system (disk full, read-only): one line naming it."""
    try:
        yield
    except sqlite3.Error as error:
        code = getattr(error, "sqlite_errorcode", None)
        if code is None or code & 0xFF not in _STORAGE_REFUSED:
            raise
        raise cannot_write("--out", str(path.parent), path, str(error)) from None


@contextlib.contextmanager
def _transaction(connection: sqlite3.Connection) -> Iterator[sqlite3.Connection]:
    connection.execute("BEGIN IMMEDIATE")
    try:
        yield connection
    except BaseException:
        with contextlib.suppress(sqlite3.Error):  # a failed COMMIT may have ended it already
            connection.execute("ROLLBACK")
        raise
    connection.execute("COMMIT")


class _Store:
    """The results file of one campaign folder; only the coordinator holds one."""

    def __init__(self, out_dir: Path, campaign: Campaign) -> None:
        self.path = out_dir / RESULTS_FILE
        try:
            with _storage_errors(self.path):
                self.connection = _connect(self.path)
        except sqlite3.DatabaseError as error:  # a damaged file, or not SQLite's at all
            raise _unreadable(self.path, str(error), "--out") from None
        self.campaign = campaign
        try:
            with _storage_errors(self.path):
                self._open(out_dir, campaign)
        except sqlite3.DatabaseError as error:  # a damaged file, or not SQLite's at all
            self.connection.close()
            raise _unreadable(self.path, str(error), "--out") from None
        except BaseException:
            self.connection.close()
            raise

    def _open(self, out_dir: Path, campaign: Campaign) -> None:
        """Create the tables, or check that they hold this campaign."""
        with _transaction(self.connection) as db:
            if _has_table(db, "campaign") and not _has_table(db, "runs"):
                raise _unreadable(self.path, "no such table: runs", "--out")
            for statement in _SCHEMA.split(";"):
                if statement.strip():
                    db.execute(statement)
            row = db.execute("SELECT hash, metric_columns FROM campaign").fetchone()
            if row is not None and row[0] != campaign.hash:
                raise ConfigError(
                    "--out",
                    str(out_dir),
                    f"holds another campaign (hash {row[0][:12]}, this file {campaign.hash[:12]});"
                    " use a new folder, or --overwrite to discard it",
                )
            self.metric_columns: list[str] = json.loads(row[1]) if row else []
            db.execute(
                "INSERT INTO campaign (id, hash, name, spec, source, base_source, base_data, "
                "base_dir, parameter_columns, created_utc, auvmpc_version) "
                "VALUES (0, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?) ON CONFLICT(id) DO UPDATE SET "
                "name = excluded.name, spec = excluded.spec, source = excluded.source",
                (
                    campaign.hash,
                    campaign.spec.name,
                    json.dumps(campaign.spec.model_dump(mode="json")),
                    campaign.source,
                    campaign.base_source or "",  # none for generated cases
                    _canonical_json(campaign.base_data),
                    campaign.base_dir,
                    json.dumps(list(campaign.parameter_columns)),
                    _now(),
                    __version__,
                ),
            )
            self._create_view(db)

    def close(self) -> None:
        self.connection.close()

    def record_session(self, provenance: Mapping[str, Any], new_runs: int) -> None:
        """One coordinator session (``provenance``: interfaces.md keys), in one transaction."""
        with _storage_errors(self.path), _transaction(self.connection) as db:
            db.execute(
                "INSERT INTO sessions (started_utc, wall_s, new_runs, provenance) "
                "VALUES (?, ?, ?, ?)",
                (
                    provenance["started_utc"],
                    provenance["wall_s"],
                    new_runs,
                    json.dumps(provenance),
                ),
            )

    def finished(self) -> set[int]:
        return {row[0] for row in self.connection.execute('SELECT "index" FROM runs')}

    def deaths(self) -> dict[int, int]:
        return dict(self.connection.execute('SELECT "index", deaths FROM worker_deaths'))

    def add_death(self, index: int) -> int:
        with _storage_errors(self.path), _transaction(self.connection) as db:
            db.execute(
                'INSERT INTO worker_deaths ("index", deaths) VALUES (?, 1) '
                'ON CONFLICT("index") DO UPDATE SET deaths = deaths + 1',
                (index,),
            )
            return db.execute(
                'SELECT deaths FROM worker_deaths WHERE "index" = ?', (index,)
            ).fetchone()[0]

    def record(self, result: Mapping[str, Any]) -> None:
        """One finished run, in one transaction."""
        metrics = _finite_or_none(result["metrics"])
        index = result["index"]
        with _storage_errors(self.path), _transaction(self.connection) as db:
            deaths = db.execute(
                'SELECT deaths FROM worker_deaths WHERE "index" = ?', (index,)
            ).fetchone()
            db.execute(
                'INSERT INTO runs ("index", seed, status, error, traceback, parameters, '
                "metrics, wall_s, worker_deaths, worker, finished_utc) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    index,
                    result["seed"],
                    result["status"],
                    result["error"],
                    result["traceback"],
                    json.dumps(_finite_or_none(result["parameters"]), allow_nan=False),
                    json.dumps(metrics, allow_nan=False),
                    result["wall_s"],
                    deaths[0] if deaths else 0,
                    result["worker"],
                    _now(),
                ),
            )
            new = [key for key in metrics if key not in self.metric_columns]
            if new:
                self.metric_columns += new
                db.execute(
                    "UPDATE campaign SET metric_columns = ?", (json.dumps(self.metric_columns),)
                )
                self._create_view(db)

    def _create_view(self, db: sqlite3.Connection) -> None:
        """``results``: one column per parameter and metric, for SQL queries (the exact
        floats come from :func:`load_results`, which parses the JSON in Python)."""
        columns = ['"index"', "seed", "status", "error"]
        for name in self.campaign.parameter_columns:
            columns.append(
                f"json_extract(parameters, {_sql_text(_json_path(name))}) AS {_sql_name(name)}"
            )
        for name in self.metric_columns:
            columns.append(
                f"json_extract(metrics, {_sql_text(_json_path(name))}) AS {_sql_name(name)}"
            )
        columns += ["wall_s", "worker_deaths"]
        db.execute("DROP VIEW IF EXISTS results")
        db.execute(f"CREATE VIEW results AS SELECT {', '.join(columns)} FROM runs")


def _sql_name(name: str) -> str:
    return '"' + name.replace('"', '""') + '"'


def _sql_text(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"


def _json_path(key: str) -> str:
    return '$."' + key.replace('"', '\\"') + '"'


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def _finite_or_none(values: Mapping[str, Any]) -> dict[str, Any]:
    """JSON-ready: NaN and infinities become null (SQLite's JSON rejects them)."""
    return {
        key: None if isinstance(value, float) and not math.isfinite(value) else value
        for key, value in values.items()
    }


@contextlib.contextmanager
def _exclusive(out_dir: Path) -> Iterator[None]:
    """One coordinator per folder (released by the OS even on SIGKILL)."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock
        yield
        return
    with output_errors("--out", str(out_dir)):
        handle = open(out_dir / LOCK_FILE, "a")  # closed by the with below
    with handle:
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise ConfigError(
                "--out", str(out_dir), "another campaign process is writing here"
            ) from None
        try:
            yield
        finally:
            fcntl.flock(handle.fileno(), fcntl.LOCK_UN)


def count_finished(out_dir: str | Path) -> int:
    """Rows stored in a campaign folder (0 if it has no results file yet)."""
    path = Path(out_dir) / RESULTS_FILE
    if not path.is_file():
        return 0
    with _reading(Path(out_dir)) as db:
        try:
            return int(db.execute("SELECT COUNT(*) FROM runs").fetchone()[0])
        except sqlite3.OperationalError:  # created, tables not yet
            return 0


def stored_sessions(out_dir: str | Path) -> list[dict[str, Any]]:
    """Provenance of every session that ran runs of a campaign folder, oldest first."""
    with _reading(Path(out_dir)) as db:
        if not _has_table(db, "sessions"):  # a folder written before sessions were recorded
            return []
        rows = db.execute("SELECT provenance, new_runs FROM sessions ORDER BY rowid").fetchall()
        return [{**json.loads(text), "new_runs": new_runs} for text, new_runs in rows]


def _has_table(db: sqlite3.Connection, name: str) -> bool:
    found = db.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (name,))
    return found.fetchone() is not None


def stored_campaign(out_dir: Path) -> Campaign:
    """The campaign a results folder was written by (as stored, not as the file is now)."""
    with _reading(Path(out_dir)) as db:
        spec_text, source, base_source, base_data, base_dir = _campaign_row(
            db, out_dir, "spec, source, base_source, base_data, base_dir"
        )
        spec = CampaignSpec.model_validate(json.loads(spec_text))
        return _with_implicit_overrides(
            Campaign(
                spec,
                source,
                None if spec.cases is not None else base_source,
                json.loads(base_data),
                base_dir,
                controller_overrides=expand_controller(spec.controller),
            )
        )


def stored_version(out_dir: Path) -> str:
    """The auvmpc version that created a results folder."""
    with _reading(Path(out_dir)) as db:
        return _campaign_row(db, out_dir, "auvmpc_version")[0]


def stored_metrics(out_dir: Path) -> dict[int, dict[str, Any]]:
    """Run index -> metrics, of the runs stored with status ``ok`` (floats exactly as the
    runs computed them: the JSON is parsed by Python)."""
    with _reading(Path(out_dir)) as db:
        rows = db.execute('SELECT "index", metrics FROM runs WHERE status = ?', ("ok",)).fetchall()
        return {index: json.loads(text) for index, text in rows}


def _campaign_row(db: sqlite3.Connection, out_dir: Path, columns: str) -> tuple[Any, ...]:
    row = db.execute(f"SELECT {columns} FROM campaign").fetchone()
    if row is None:
        raise ConfigError("DIR", str(out_dir), "no campaign stored in results.sqlite")
    return row


def _results_path(out_dir: Path) -> Path:
    path = Path(out_dir) / RESULTS_FILE
    if not path.is_file():
        raise ConfigError("DIR", str(out_dir), f"no campaign results here ({RESULTS_FILE} missing)")
    return path
