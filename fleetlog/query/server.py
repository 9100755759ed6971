"""The vehicle side of the query services: queryables over a log root.

:class:`LogServer` declares four queryables under ``<root>/V/@fleetlog/`` (``latest``,
``sessions``, ``file/*/*``, ``grep/*``; the protocol is :mod:`fleetlog.wire.query`) and, when
it runs on its own (``fleetlog serve``), the liveliness token ``<root>/V/@fleetlog/serve``.

Threads. Each queryable delivers into a Zenoh FIFO channel drained by one dispatcher thread
(:class:`~fleetlog.transport.queries.ServiceQueryable`), so Zenoh's network threads never
wait for Python's GIL on a query (a callback would: while a grep holds the GIL, every query
callback would stall the link that also carries the recorder's samples). The dispatcher only
hands the query to a worker pool: a *light* pool for
``latest``, brief listings and byte ranges, a *heavy* one for full listings, sha256 and grep,
so a long grep never delays a download. Each pool takes a bounded number of pending
requests; beyond it a request is refused at once ("busy") instead of queueing without end.
The recorder's drain thread shares no lock with any of this: the server learns the active
session by calling the recorder's ``active`` function, which reads one attribute.

Digests ahead of time. A first fetch of a file whose digest nobody computed yet makes the
vehicle hash it while it serves it (:meth:`DigestCache.feed`): on a 2-core vehicle that CPU is
taken from the transfer. So a *warmer* thread hashes, before anyone asks, the latest session
when the server starts (if it is complete) and each session the recorder closes, at most half
of a core and only while no request arrived for half a second (not by thread priority: a
low-priority thread holding the GIL would stall the recorder).

Every request ends with replies or with one ``reply_err`` whose text says what was wrong; an
unexpected exception is reported the same way ("internal error: ...") and logged, and the
server keeps serving.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from types import TracebackType

from fleetlog.errors import FleetlogError, FormatError, TransportError
from fleetlog.query.grep import run_grep
from fleetlog.storage.catalog import LogCatalog
from fleetlog.transport.queries import (
    IncomingQuery,
    LivelinessToken,
    ServiceQueryable,
    ZenohSession,
    declare_token,
    session_zid,
)
from fleetlog.wire.keys import DEFAULT_ROOT, check_root, service_key
from fleetlog.wire.query import (
    FILE,
    GREP,
    LATEST,
    SERVE_TOKEN,
    SESSIONS,
    FileMeta,
    GrepHeader,
    file_key,
    grep_key,
    parse_file_request,
    parse_grep_request,
    parse_service_parts,
    parse_sessions_request,
    sessions_to_json,
    split_server,
)

__all__ = ["LogServer"]

_log = logging.getLogger("fleetlog.query.server")
#: the warmer waits for this long without requests before it hashes on
_WARM_QUIET = 0.5
#: how often the warmer looks whether the recorder closed its session (unless it is told)
_WARM_POLL = 2.0
_JSON = "application/json"
_BYTES = "application/octet-stream"
_NDJSON = "application/x-ndjson"


class _Pool:
    """A thread pool that refuses work beyond ``pending`` queued or running requests."""

    def __init__(self, name: str, workers: int, pending: int) -> None:
        self._executor = ThreadPoolExecutor(workers, thread_name_prefix=name)
        self._slots = threading.BoundedSemaphore(pending)

    def submit(self, fn: Callable[[], None]) -> bool:
        if not self._slots.acquire(blocking=False):
            return False

        def run() -> None:
            try:
                fn()
            finally:
                self._slots.release()

        try:
            self._executor.submit(run)
        except RuntimeError:  # shut down meanwhile
            self._slots.release()
            return False
        return True

    def shutdown(self) -> None:
        self._executor.shutdown(wait=True)


class LogServer:
    """Serves a log root's sessions over Zenoh queryables.

    Use it as a context manager, or call :meth:`start` and :meth:`close`::

        catalog = LogCatalog(log_root, vehicle="alpha", active=lambda: recorder_dir())
        with LogServer(session, catalog, root="fleet"):
            ...

    Args:
        session: an open Zenoh session (not closed here).
        catalog: the log root to serve.
        root: the key root.
        vehicle: the vehicle whose keys are served; the catalog's by default.
        announce: declare the ``serve`` liveliness token (``fleetlog serve``; the recorder
            has its own ``recorder`` token). Without it the server is the recorder's, and
            its replies name it as the vehicle's ``recorder``.
        workers: threads of the light pool (ranges, latest, brief listings).
        heavy_workers: threads of the heavy pool (full listings, sha256, grep).
        warm: hash the latest session at start and each session the recorder closes, before
            anyone asks (see the module docstring).
        session_changes: set by the recorder whenever it opens or closes a session (the
            recorder's own server): the warmer waits on it, instead of looking every 2 s
            whether the recorder closed its session.

    Raises:
        FormatError: the key root is not usable.
    """

    def __init__(
        self,
        session: ZenohSession,
        catalog: LogCatalog,
        *,
        root: str = DEFAULT_ROOT,
        vehicle: str | None = None,
        announce: bool = False,
        workers: int = 4,
        heavy_workers: int = 2,
        warm: bool = True,
        session_changes: threading.Event | None = None,
    ) -> None:
        self.session = session
        self.catalog = catalog
        self.root = check_root(root)
        self.vehicle = vehicle if vehicle is not None else catalog.vehicle
        self.announce = announce
        #: this process's Zenoh id: replies name it, and ``server=ZID`` requests match it
        self.zid = session_zid(session)
        self._recorder = None if announce else self.zid
        self.stats: dict[str, int] = {"requests": 0, "errors": 0, "refused": 0, "bytes": 0}
        self._stats_lock = threading.Lock()
        self._light = _Pool("fleetlog-serve", workers, 64)
        self._heavy = _Pool("fleetlog-serve-heavy", heavy_workers, 16)
        self._closing = threading.Event()
        self._queryables: list[ServiceQueryable] = []
        self._token: LivelinessToken | None = None
        self._started = False
        self._warm = warm
        self._warmer: threading.Thread | None = None
        self._changes = session_changes
        self._last_request = 0.0

    # -- lifecycle

    def start(self) -> LogServer:
        """Declare the queryables (and the ``serve`` token); return self.

        Raises:
            TransportError: Zenoh refused a declaration.
        """
        if self._started:
            return self
        self._started = True
        routes: list[tuple[str, Callable[[IncomingQuery], None]]] = [
            (service_key(self.root, self.vehicle, LATEST), self._on_latest),
            (service_key(self.root, self.vehicle, SESSIONS), self._on_sessions),
            (service_key(self.root, self.vehicle, FILE, "*", "*"), self._on_file),
            (service_key(self.root, self.vehicle, GREP, "*"), self._on_grep),
        ]
        try:
            for key, handler in routes:
                self._queryables.append(ServiceQueryable(self.session, key, handler))
            if self.announce:
                token_key = service_key(self.root, self.vehicle, SERVE_TOKEN)
                self._token = declare_token(self.session, token_key)
        except BaseException:
            self.close()
            raise
        if self._warm:
            self._warmer = threading.Thread(
                target=self._warm_loop, name="fleetlog-serve-warm", daemon=True
            )
            self._warmer.start()
        return self

    def close(self) -> None:
        """Stop serving: undeclare everything, let running requests finish or abort.

        Requests still queued are answered "the log server is closing"; a running grep or
        hash stops at its next check. Safe to call twice.
        """
        self._closing.set()
        if self._changes is not None:
            self._changes.set()  # the warmer waits on it
        if self._token is not None:
            self._token.undeclare()
            self._token = None
        for queryable in self._queryables:
            queryable.undeclare()
        self._queryables.clear()
        self._light.shutdown()
        self._heavy.shutdown()
        self.catalog.leases.close()  # no more fetches in flight from this process
        if self._warmer is not None:
            self._warmer.join(5.0)
            self._warmer = None

    def __enter__(self) -> LogServer:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- dispatching

    def _mine(self, query: IncomingQuery) -> bool:
        """Take out ``server=ZID``; False (and the query finished) if it asks another process.

        Two processes serving one vehicle both receive every query; the one not named stays
        silent, so the querier hears only the one it asked.
        """
        try:
            server, rest = split_server(query.parameters)
        except FormatError as err:
            query.reply_err(str(err))
            query.finish()
            return False
        if server is not None and server != self.zid:
            query.finish()
            return False
        query.parameters = rest
        return True

    def _count(self, name: str, amount: int = 1) -> None:
        with self._stats_lock:
            self.stats[name] += amount

    def _submit(
        self, pool: _Pool, query: IncomingQuery, work: Callable[[IncomingQuery], None]
    ) -> None:
        self._count("requests")
        self._last_request = time.monotonic()
        if not pool.submit(lambda: self._run(query, work)):
            self._count("refused")
            query.reply_err("the log server is busy; try again shortly")
            query.finish()

    def _run(self, query: IncomingQuery, work: Callable[[IncomingQuery], None]) -> None:
        try:
            if self._closing.is_set():
                query.reply_err("the log server is closing")
                return
            work(query)
        except TransportError as err:
            self._count("errors")
            _log.info("request %s: the reply failed: %s", query.selector, err)
        except FleetlogError as err:
            self._count("errors")
            query.reply_err(self._public(str(err)))
        except Exception as err:  # a bad request must never stop the server
            self._count("errors")
            _log.exception("request %s failed", query.selector)
            query.reply_err(self._public(f"internal error: {type(err).__name__}: {err}"))
        finally:
            query.finish()

    def _public(self, text: str) -> str:
        """Say paths relative to the log root: shore has no business with the vehicle's layout."""
        root = str(self.catalog.root.path)
        return text.replace(root + "/", "").replace(root, "<log root>")

    # -- digests ahead of time

    def _warm_loop(self) -> None:
        try:
            latest = self.catalog.latest()
            if latest.session is not None and not latest.writing:
                self._warm_session(latest.session)
            previous = self.catalog.active_session()
            while self._wait_for_change():
                active = self.catalog.active_session()
                if previous is not None and active != previous:
                    self._warm_session(previous)  # the recorder closed it
                previous = active
        except Exception:  # the warmer must never take the server down
            _log.exception("hashing sessions ahead of time failed")

    def _wait_for_change(self) -> bool:
        """Wait until the recorder's session may have changed; False once closing."""
        changes = self._changes
        if changes is None:
            return not self._closing.wait(_WARM_POLL)
        changes.wait()
        changes.clear()
        return not self._closing.is_set()

    def _warm_session(self, session: str) -> None:
        try:
            self.catalog.warm_digests(session, self._closing, self._warm_pause)
        except FleetlogError as err:
            _log.info("hashing session %s ahead of time: %s", session, err)

    def _warm_pause(self, took: float) -> None:
        # Half a core at most, and nothing while requests are being served.
        self._closing.wait(took)
        while not self._closing.is_set():
            quiet = time.monotonic() - self._last_request
            if quiet >= _WARM_QUIET:
                return
            self._closing.wait(_WARM_QUIET - quiet)

    @staticmethod
    def _names(query: IncomingQuery, service: str) -> tuple[str, ...]:
        found, names = parse_service_parts(query.key)
        if found != service:  # pragma: no cover - the queryable's key decides the service
            msg = f"this queryable serves {service}, not {found}"
            raise FormatError(msg)
        return names

    # -- services

    def _on_latest(self, query: IncomingQuery) -> None:
        if self._mine(query):
            self._submit(self._light, query, self._latest)

    def _latest(self, query: IncomingQuery) -> None:
        self._names(query, LATEST)
        if query.parameters:
            msg = f"the latest service takes no parameters, got {query.parameters[:80]!r}"
            raise FormatError(msg)
        info = dataclasses.replace(self.catalog.latest(), server=self.zid, recorder=self._recorder)
        key = service_key(self.root, self.vehicle, LATEST)
        query.reply(key, info.to_json(), encoding=_JSON)

    def _on_sessions(self, query: IncomingQuery) -> None:
        if not self._mine(query):
            return
        try:
            brief = parse_sessions_request(query.parameters).brief
        except FormatError:
            brief = True  # refused quickly by the worker
        self._submit(self._light if brief else self._heavy, query, self._sessions)

    def _sessions(self, query: IncomingQuery) -> None:
        self._names(query, SESSIONS)
        request = parse_sessions_request(query.parameters)
        if request.session is not None:
            infos = [self.catalog.session(request.session, brief=request.brief)]
        else:
            infos = self.catalog.sessions(brief=request.brief)
        key = service_key(self.root, self.vehicle, SESSIONS)
        replies = sessions_to_json(self.vehicle, infos, server=self.zid, recorder=self._recorder)
        for payload in replies:
            query.reply(key, payload, encoding=_JSON)

    def _on_file(self, query: IncomingQuery) -> None:
        if not self._mine(query):
            return
        try:
            digest = parse_file_request(query.parameters).sha256
        except FormatError:
            digest = False
        self._submit(self._heavy if digest else self._light, query, self._file)

    def _file(self, query: IncomingQuery) -> None:
        session, name = self._names(query, FILE)
        request = parse_file_request(query.parameters)
        data, meta, sent = self.catalog.serve_range(session, name, request.offset, request.length)
        if request.sha256 and meta.complete:
            digest = self.catalog.file_digest(session, name, self._closing)
            if digest.size == meta.size and digest.mtime == meta.mtime:
                meta = FileMeta(
                    meta.offset, meta.length, meta.size, meta.mtime, meta.complete, digest.sha256
                )
        key = file_key(self.root, self.vehicle, session, name)
        query.reply(key, data, encoding=_BYTES, attachment=meta.to_json())
        self._count("bytes", len(data))
        # The client's request ends when the query is finished, not with the reply: finish
        # it before hashing the range into the file's digest, or the hash delays the client.
        query.finish()
        sent()

    def _on_grep(self, query: IncomingQuery) -> None:
        if self._mine(query):
            self._submit(self._heavy, query, self._grep)

    def _grep(self, query: IncomingQuery) -> None:
        (session,) = self._names(query, GREP)
        request = parse_grep_request(query.parameters)
        alog, head = self.catalog.head(session)
        header = GrepHeader(
            session=session,
            alog=alog,
            logstart=head.banner.logstart if head.banner else None,
            banner=head.banner_lines,
            time_decimals=head.time_decimals if head.time_decimals is not None else 5,
            mark_data_type=head.banner.mark_data_type if head.banner else False,
        )
        key = grep_key(self.root, self.vehicle, session)
        path = self.catalog.root.resolve(session, alog)

        def emit(chunk: bytes) -> None:
            query.reply(key, chunk, encoding=_NDJSON)

        run_grep(path, header, request, emit, self._closing)
