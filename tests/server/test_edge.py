"""The service's edge against a real server: body limits before work, the token before the body, trusted hosts,
same-origin mutations and the view's websocket."""

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import psutil
import pytest
import viser
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

from driftlab.db import storage
from tests.server_process import free_port, start_server, wait_status

pytestmark = pytest.mark.e2e  # real processes: servers, browsers, Dask, the CLI

TOKEN = "edge-test-token"
SUBPROTOCOL = f"viser-v{viser.__version__}"


@pytest.fixture(scope="module")
def open_server(tmp_path_factory):
    proc, url = start_server(tmp_path_factory.mktemp("edge") / "open.db", free_port())
    yield proc, url
    proc.terminate()
    proc.wait(timeout=30)


@pytest.fixture(scope="module")
def token_server(tmp_path_factory):
    proc, url = start_server(tmp_path_factory.mktemp("edge") / "token.db", free_port(),
                             env_extra={"DRIFTLAB_TOKEN": TOKEN})
    yield proc, url
    proc.terminate()
    proc.wait(timeout=30)


def _chunks(total_mb=300):
    block = b"x" * (1 << 20)
    for _ in range(total_mb):
        yield block


def _post_huge(url, headers, sized):
    """A 300 MB POST (with a Content-Length, or chunked); the server may close while the client still writes."""
    if sized:
        headers = {**headers, "content-length": str(300 << 20)}
    try:
        return httpx.post(f"{url}/api/jobs", content=_chunks(), headers=headers, timeout=60).status_code
    except (httpx.WriteError, httpx.RemoteProtocolError, httpx.ReadError):
        return None  # refused before the client finished sending


@pytest.mark.parametrize("sized", [True, False])
@pytest.mark.parametrize("which", ["open", "token"])
def test_a_300_mb_body_is_refused_before_it_is_read(open_server, token_server, which, sized):
    proc, url = open_server if which == "open" else token_server
    rss_before = psutil.Process(proc.pid).memory_info().rss
    status = _post_huge(url, {"content-type": "application/json"}, sized)
    assert status in (413, 401, None)
    if which == "token":  # no token: refused with 401 before a byte of the body is read
        assert status in (401, None)
    growth_mb = (psutil.Process(proc.pid).memory_info().rss - rss_before) / 2**20
    assert growth_mb < 50, growth_mb
    # The server is fine afterwards, and a small body still gets through.
    assert httpx.get(f"{url}/api/health").status_code == 200


def test_a_sized_body_over_the_limit_is_a_413_naming_the_limit(open_server):
    _, url = open_server
    r = httpx.post(f"{url}/api/jobs", content=b"{" + b" " * 1_100_000 + b"}",
                   headers={"content-type": "application/json"})
    assert r.status_code == 413 and "DRIFTLAB_MAX_BODY_BYTES" in r.json()["detail"]


def test_a_foreign_host_is_400_and_a_foreign_origin_may_not_mutate(open_server):
    _, url = open_server
    assert httpx.get(f"{url}/api/jobs", headers={"host": "evil.example"}).status_code == 400
    r = httpx.post(f"{url}/api/jobs/1/pause", headers={"origin": "http://evil.example"})
    assert r.status_code == 403 and "origin" in r.json()["detail"]
    same = httpx.post(f"{url}/api/jobs/1/pause", headers={"origin": url})
    assert same.status_code == 404  # past the edge: no such job
    assert httpx.get(f"{url}/api/jobs", headers={"origin": "http://evil.example"}).status_code == 200  # reads


def test_the_openapi_document_states_the_edge(open_server, token_server):
    """The bearer scheme and its 401 only when a token is set; without one, the 403 for another origin."""
    open_doc = httpx.get(f"{open_server[1]}/openapi.json").json()
    token_doc = httpx.get(f"{token_server[1]}/openapi.json").json()
    create = open_doc["paths"]["/api/jobs"]["post"]
    assert "security" not in create and {"400", "403", "413", "422"} <= set(create["responses"])
    assert "401" not in create["responses"] and "securitySchemes" not in open_doc["components"]
    create = token_doc["paths"]["/api/jobs"]["post"]
    assert create["security"] == [{"bearerToken": []}] and "401" in create["responses"]
    assert token_doc["components"]["securitySchemes"]["bearerToken"]["scheme"] == "bearer"
    assert token_doc["paths"]["/api/jobs"]["get"]["security"] == [{"bearerToken": []}]  # reads need it too
    assert "security" not in token_doc["paths"]["/api/health"]["get"]  # the liveness probe has none
    error = create["responses"]["409"]["content"]["application/json"]["schema"]
    assert error == {"$ref": "#/components/schemas/ErrorBody"}


def test_an_unsupported_method_is_a_405_allowing_every_method_of_the_path(open_server):
    _, url = open_server
    r = httpx.request("OPTIONS", f"{url}/api/jobs/1")
    assert r.status_code == 405 and r.headers["allow"] == "GET, PATCH, DELETE"
    r = httpx.put(f"{url}/api/jobs", json={})
    assert r.status_code == 405 and r.headers["allow"] == "GET, POST" and r.json()["detail"]


def _ws(url, **kwargs):
    return connect(url.replace("http", "ws") + "/viser", subprotocols=[SUBPROTOCOL], open_timeout=10, **kwargs)


def test_the_view_websocket_needs_this_origin(open_server):
    _, url = open_server
    with pytest.raises(InvalidStatus) as refused:
        _ws(url, origin="http://evil.example")
    assert refused.value.response.status_code == 403
    with _ws(url, origin=url) as socket:
        assert socket.recv(timeout=10)  # viser speaks first


def test_the_view_websocket_needs_the_token_when_one_is_set(token_server):
    _, url = token_server
    with pytest.raises(InvalidStatus):
        _ws(url, origin=url)
    page = httpx.get(f"{url}/viser/", params={"token": TOKEN, "playbackPath": "/x.viser"})
    cookie = page.cookies.get("driftlab_token")
    # The token moves into an HttpOnly cookie and out of the address: a 303 to the page without it.
    assert page.status_code == 303 and cookie == TOKEN and page.headers["location"] == "/viser/?playbackPath=%2Fx.viser"
    assert "httponly" in page.headers["set-cookie"].lower() and "samesite=strict" in page.headers["set-cookie"].lower()
    assert "secure" not in page.headers["set-cookie"].lower()  # plain http on loopback
    behind_https = httpx.get(f"{url}/viser/", params={"token": TOKEN}, headers={"x-forwarded-proto": "https"})
    assert "secure" in behind_https.headers["set-cookie"].lower()
    wrong = httpx.get(f"{url}/viser/", params={"token": "wrong"})
    assert wrong.status_code == 303 and "set-cookie" not in wrong.headers
    with _ws(url, origin=url, additional_headers={"cookie": f"driftlab_token={cookie}"}) as socket:
        assert socket.recv(timeout=10)


def test_a_websocket_opened_with_the_token_in_its_address_leaves_no_line_holding_it(token_server):
    """A script may put the token in the websocket's address: uvicorn logs websocket lines through its error log,
    not the access log, and every line the server writes is redacted."""
    proc, url = token_server
    ws_url = url.replace("http://", "ws://") + f"/viser?token={TOKEN}"
    with connect(ws_url, origin=url, subprotocols=[SUBPROTOCOL], open_timeout=30) as socket:
        assert socket.recv(timeout=10)  # accepted: the token in the address is a credential like the cookie

    def logged() -> str:
        return Path(proc.log_path).read_text()
    deadline = time.monotonic() + 10
    while "WebSocket /viser" not in logged() and time.monotonic() < deadline:
        time.sleep(0.1)
    text = logged()
    assert '"WebSocket /viser?token=[redacted]" [accepted]' in text
    assert TOKEN not in text


def test_a_malformed_token_is_a_401_never_a_500(token_server):
    _, url = token_server
    for given in ("Bearer \u00e9t\u00e9", "Bearer " + "x" * 5000, "Basic abc", ""):
        r = httpx.post(f"{url}/api/jobs", json={}, headers={"authorization": given.encode("utf-8")})
        assert r.status_code == 401, (given[:20], r.status_code)
    r = httpx.post(f"{url}/api/jobs", json={}, headers={"cookie": "driftlab_token=\u00e9".encode()})
    assert r.status_code == 401


def test_serving_beyond_this_machine_needs_a_token(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "DRIFTLAB_TOKEN"}
    out = subprocess.run([sys.executable, "-m", "driftlab.cli", "serve", "--host", "0.0.0.0", "--port",
                          str(free_port()), "--db", str(tmp_path / "x.db")], env=env, capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 2 and "DRIFTLAB_TOKEN" in out.stderr
    assert not (tmp_path / "x.db").exists()  # refused before anything was opened


def test_work_per_request_is_bounded_and_a_refusal_stores_nothing(open_server):
    _, url = open_server
    before = len(httpx.get(f"{url}/api/jobs").json())
    r = httpx.post(f"{url}/api/jobs", json={"iterations": 5000, "robust_samples": 60})
    assert r.status_code == 422 and "DRIFTLAB_MAX_EPISODES_PER_JOB" in r.json()["detail"]
    spec = {"iterations": 5000, "robust_samples": 4, "confirm_samples": 4}
    r = httpx.post(f"{url}/api/studies", json={"kind": "seeds", "seeds": list(range(32)), "spec": spec})
    assert r.status_code == 422 and r.json()["detail"].startswith("seeds:")
    assert "DRIFTLAB_MAX_EPISODES_PER_STUDY" in r.json()["detail"]
    assert len(httpx.get(f"{url}/api/jobs").json()) == before and httpx.get(f"{url}/api/studies").json() == []


def test_the_queue_is_bounded(tmp_path):
    proc, url = start_server(tmp_path / "queue.db", free_port(), env_extra={"DRIFTLAB_MAX_QUEUED_JOBS": "2"},
                             extra_args=("--workers", "1"))  # one job runs at a time
    try:
        first = httpx.post(f"{url}/api/jobs", json={"iterations": 5000, "seed_points": 5}).json()["id"]
        wait_status(url, first, {"running"})  # it runs; the next two wait
        ids = [first] + [httpx.post(f"{url}/api/jobs", json={"iterations": 5000, "seed_points": 5}).json()["id"]
                         for _ in range(2)]
        r = httpx.post(f"{url}/api/jobs", json={"iterations": 10})
        assert r.status_code == 422 and "DRIFTLAB_MAX_QUEUED_JOBS" in r.json()["detail"]
        for job_id in ids:
            httpx.post(f"{url}/api/jobs/{job_id}/pause")
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def test_a_read_only_database_is_a_json_503_and_a_newer_one_a_one_line_exit_2(tmp_path):
    db = tmp_path / "ro.db"
    storage.close_database(storage.open_database(f"sqlite:///{db}"))  # at the head revision, as a server makes it
    # Opened read-only (SQLite's mode=ro: even root cannot write through it), as a file on a read-only mount is.
    proc, url = start_server(f"sqlite:///file:{db}?mode=ro&uri=true", free_port())
    try:
        assert httpx.get(f"{url}/api/jobs").json() == []
        r = httpx.post(f"{url}/api/jobs", json={"iterations": 5})
        assert r.status_code == 503 and r.json()["detail"].startswith("storage:") and "readonly" in r.text
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    import sqlite3

    with sqlite3.connect(db) as connection:
        connection.execute("UPDATE alembic_version SET version_num = '9999'")
    out = subprocess.run([sys.executable, "-m", "driftlab.cli", "tune", "--iterations", "1", "--db", str(db)],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1 and "newer" in out.stderr


def test_sigterm_stops_tune_like_ctrl_c(tmp_path):
    import signal
    import sqlite3
    import time

    db = tmp_path / "term.db"
    proc = subprocess.Popen([sys.executable, "-m", "driftlab.cli", "tune", "--iterations", "2000", "--seed-points",
                             "5", "--name", "term", "--db", str(db), "--workers", "2"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while time.time() < deadline:  # until evaluations are being stored
        if db.exists():
            with sqlite3.connect(db) as connection:
                try:
                    if connection.execute("SELECT count(*) FROM evaluations").fetchone()[0] >= 3:
                        break
                except sqlite3.OperationalError:
                    pass
        time.sleep(0.2)
    workers = [c.pid for c in psutil.Process(proc.pid).children(recursive=True)]
    proc.send_signal(signal.SIGTERM)
    try:
        _, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:  # ended here, not left running without its parent
        proc.kill()
        _, err = proc.communicate()
    assert proc.returncode == 130, err
    with sqlite3.connect(db) as connection:
        status, runner = connection.execute("SELECT status, runner_id FROM jobs WHERE name = 'term'").fetchone()
    assert status == "paused" and runner is None  # the lease released at once, not left to go stale
    time.sleep(1.0)
    assert workers and not [p for p in workers if psutil.pid_exists(p) and psutil.Process(p).status() != "zombie"]


def _refused_post(url, path, body, pause_s):
    """A POST without the token whose body arrives ``pause_s`` after its headers (a client on a slow link, or
    requests, which writes the two separately); returns every byte the server sent back."""
    host, port = url.removeprefix("http://").split(":")
    with socket.create_connection((host, int(port)), timeout=10) as sock:
        sock.sendall(f"POST {path} HTTP/1.1\r\nHost: {host}:{port}\r\ncontent-type: application/json\r\n"
                     f"content-length: {len(body)}\r\n\r\n".encode())
        time.sleep(pause_s)
        sock.sendall(body)
        answer = b""
        while chunk := sock.recv(65536):
            answer += chunk
    return answer


def test_a_refused_request_is_answered_in_full_after_its_body(token_server):
    """A refusal waits for the (small, declared) body before it closes the connection: closing on unread bytes
    resets it, and the client loses the answer it was reading."""
    _, url = token_server
    for attempt in range(300):
        try:
            answer = _refused_post(url, "/api/jobs/1/rescore", b'{"samples": 20}', pause_s=(attempt % 6) * 4e-4)
        except ConnectionResetError:
            raise AssertionError(f"attempt {attempt}: the connection was reset before the answer was read") from None
        head, _, body = answer.partition(b"\r\n\r\n")
        assert head.startswith(b"HTTP/1.1 401") and b"Authorization: Bearer" in body, answer


def test_no_port_but_the_apis_answers_a_stranger(open_server):
    """viser's own loopback port refuses every websocket and page request that does not come through the API's relay
    (a local process, or a page any site opened in a local browser), whatever its Origin."""
    proc, url = open_server
    api_port = int(url.rsplit(":", 1)[1])
    listening = {c.laddr.port for c in psutil.Process(proc.pid).net_connections(kind="tcp")
                 if c.status == psutil.CONN_LISTEN}
    others = listening - {api_port}
    assert api_port in listening and others  # viser's port is there, and closed to strangers
    for port in others:
        for origin in (url, f"http://127.0.0.1:{port}", "http://evil.example"):
            with pytest.raises(InvalidStatus) as refused:
                connect(f"ws://127.0.0.1:{port}/", subprotocols=[SUBPROTOCOL], origin=origin, open_timeout=10)
            assert refused.value.response.status_code == 403
        assert httpx.get(f"http://127.0.0.1:{port}/").status_code == 403
    assert set(httpx.get(f"{url}/api/view").json()) == {"clients"}  # names no port
    with _ws(url, origin=url) as socket:  # the relay still gets through
        assert socket.recv(timeout=10)


def test_view_tabs_past_the_cap_are_told_to_come_back(tmp_path):
    proc, url = start_server(tmp_path / "tabs.db", free_port(), env_extra={"DRIFTLAB_MAX_VIEW_TABS": "2"})
    try:
        with _ws(url, origin=url) as first, _ws(url, origin=url) as second:
            assert first.recv(timeout=10) and second.recv(timeout=10)
            with _ws(url, origin=url) as third, pytest.raises(ConnectionClosed) as closed:
                third.recv(timeout=10)
            assert closed.value.rcvd.code == 1013 and "DRIFTLAB_MAX_VIEW_TABS" in closed.value.rcvd.reason
        deadline = time.time() + 10
        while True:  # the tabs closed: there is room again once the relay has seen them go
            with _ws(url, origin=url) as again:
                try:
                    assert again.recv(timeout=10)
                    break
                except ConnectionClosed:
                    assert time.time() < deadline, "no room after the tabs closed"
            time.sleep(0.2)
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def _read_until_closed(sock, limit_s):
    """Every byte until the server closes the connection; the seconds it took (AssertionError past ``limit_s``)."""
    start, answer = time.monotonic(), b""
    sock.settimeout(limit_s)
    try:
        while chunk := sock.recv(65536):
            answer += chunk
    except TimeoutError:
        raise AssertionError(f"still open after {limit_s} s: {answer[:200]!r}") from None
    except ConnectionResetError:
        pass
    return answer, time.monotonic() - start


def test_slow_clients_are_closed(tmp_path):
    """Headers that trickle (on a fresh connection and on a kept-alive one) and bodies that stop are given up after
    their deadlines (1 s here), with and without a token."""
    env = {"DRIFTLAB_HEADER_TIMEOUT_S": "1", "DRIFTLAB_BODY_TIMEOUT_S": "1", "DRIFTLAB_TOKEN": TOKEN}
    proc, url = start_server(tmp_path / "slow.db", free_port(), env_extra=env)
    host, port = url.removeprefix("http://").split(":")
    try:
        with socket.create_connection((host, int(port))) as sock:  # a header line every 0.3 s, never the end
            sock.sendall(f"GET /api/jobs HTTP/1.1\r\nHost: {host}:{port}\r\n".encode())
            start = time.monotonic()
            with pytest.raises((BrokenPipeError, ConnectionResetError)):
                while time.monotonic() - start < 10:
                    sock.sendall(b"X-Slow: 1\r\n")
                    time.sleep(0.3)
            assert time.monotonic() - start < 5
        with socket.create_connection((host, int(port))) as sock:  # one request, then the next one's headers stall
            first = f"GET /api/health HTTP/1.1\r\nHost: {host}:{port}\r\n\r\n"
            sock.sendall(f"{first}GET /api/health HTTP/1.1\r\n".encode())
            answer, seconds = _read_until_closed(sock, 5)
            assert answer.startswith(b"HTTP/1.1 200") and answer.count(b"HTTP/1.1") == 1 and seconds < 5
        for headers, status in (("", b"401"), (f"Authorization: Bearer {TOKEN}\r\n", b"408")):
            with socket.create_connection((host, int(port))) as sock:  # 10 of the 1000 bytes it announced
                sock.sendall(f"POST /api/jobs HTTP/1.1\r\nHost: {host}:{port}\r\n{headers}content-type: "
                             f"application/json\r\ncontent-length: 1000\r\n\r\n{{\"name\": ".encode())
                answer, seconds = _read_until_closed(sock, 5)
                assert answer.startswith(b"HTTP/1.1 " + status) and seconds < 5, answer
        assert httpx.get(f"{url}/api/health").status_code == 200
    finally:
        proc.terminate()
        proc.wait(timeout=30)
