"""Names that read as typed: what a name may hold (driftlab.names, the API's 422 and the CLI's exit 2), how the view
and the reports escape one for markdown (driftlab.markup), and a name in a trajectory CSV (no formula cell)."""


import pytest

from driftlab.markup import plain
from driftlab.names import name_problem
from tests.server.conftest import in_process_client


@pytest.mark.parametrize(("text", "shown"), [
    ("<img src=x onerror=alert(1)>", "&lt;img src=x onerror=alert\\(1\\)&gt;"),
    ("a|b*c", "a\\|b\\*c"),
    ("![x](/y)", "\\!\\[x\\]\\(/y\\)"),
    ("R&D_1 `x` $y$", "R&amp;D\\_1 \\`x\\` \\$y\\$"),
    ("line\nbreak", "line break"),
    ("abc\u202edef", "abcdef"),  # a right-to-left override would make it read "abcfed"
])
def test_plain_escapes_html_then_markdown(text, shown):
    assert plain(text) == shown


@pytest.mark.parametrize(("name", "needle"), [
    ("a\nb", "U+000A"), ("nul\x00", "U+0000"), ("evil\u202etxt.exe", "U+202E"), ("zero\u200bwidth", "U+200B"),
    ("   ", "visible character"),
])
def test_names_with_control_or_invisible_characters_are_refused(name, needle):
    assert needle in name_problem(name)


def test_ordinary_names_pass():
    for name in ("BMW 0.55 R44", "Überholen – Δβ", "a|b*c", "<b>", "試験"):
        assert name_problem(name) is None


def test_the_api_refuses_such_a_name_naming_the_field(tmp_path):
    with in_process_client(tmp_path / "names.db") as client:
        r = client.post("/api/jobs", json={"name": "two\nlines", "iterations": 1})
        assert r.status_code == 422 and r.json()["errors"][0]["field"] == "name"
        assert "U+000A" in r.json()["detail"]
        r = client.post("/api/studies", json={"kind": "seeds", "name": "x\u202ey", "seeds": [1],
                                              "spec": {"iterations": 1}})
        assert r.status_code == 422 and r.json()["errors"][0]["field"] == "name"
        assert client.get("/api/jobs").json() == []  # nothing stored


def test_the_access_log_never_holds_the_token():
    import logging

    from driftlab.server.access_log import RedactToken

    record = logging.LogRecord("uvicorn.access", logging.INFO, __file__, 1, '%s - "%s %s HTTP/%s" %d',
                               ("127.0.0.1:5555", "GET", "/viser/?playbackPath=/x&token=s3cret&b=1", "1.1", 303),
                               None)
    assert RedactToken().filter(record)
    line = record.getMessage()
    assert "s3cret" not in line and "token=[redacted]" in line and "playbackPath=/x" in line and "b=1" in line
