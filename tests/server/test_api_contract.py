"""The REST API's contract in-process (TestClient on a real SQLite file, no worker): bad requests name the field and
store nothing, unknown ids are 404, the token guards every request but the health check."""

import re

import pytest

from tests.server.conftest import in_process_client


@pytest.mark.parametrize(("body", "field"), [
    ({"iterations": "many"}, "iterations"),
    ({"iterations": 0}, "iterations"),
    ({"iterations": 10**6}, "iterations"),
    ({"iterations": 5, "bounds": {"k": [0.1, 0.05]}}, "bounds.k"),
    ({"iterations": 5, "bounds": {"speed": [0, 1]}}, "bounds.speed"),
    ({"iterations": 5, "config": {"plant.no_such_key": 1}}, "plant.no_such_key"),
    ({"iterations": 5, "config": {"plant.friction_scale": 9.0}}, "plant.friction_scale"),
    ({"iterations": 5, "colour": "red"}, "colour"),
    ({"iterations": 5, "config": {"plant.friction_scale": 1.2}}, "not drivable"),
    ({"iterations": 5, "config": {"plant.model": "commonroad_std"}}, "steers into the turn"),  # sideslip 0.4
    ({"iterations": 5, "config": {"plant.model": "commonroad_std", "plant.commonroad_vehicle": 1,
                                  "scenario.sideslip_rad": 0.5}}, "front-wheel drive"),
])
def test_bad_requests_name_the_field_and_store_nothing(api, body, field):
    r = api.post("/api/jobs", json=body)
    assert r.status_code == 422, r.text
    assert field in r.json()["detail"]
    assert api.get("/api/jobs").json() == []


def test_a_good_request_is_stored_queued(api):
    r = api.post("/api/jobs", json={"iterations": 3, "name": "queued"})
    assert r.status_code == 201, r.text
    assert [(j["name"], j["status"], j["n_done"]) for j in api.get("/api/jobs").json()] == [("queued", "queued", 0)]


def test_unknown_ids_are_404(api):
    assert api.get("/api/jobs/999999").status_code == 404
    assert api.post("/api/jobs/999999/pause").status_code == 404
    assert api.get("/api/evaluations/999999").status_code == 404
    assert api.get("/api/evaluations/999999/trajectory").status_code == 404


def test_token_guards_every_api_request_but_the_health_check(tmp_path):
    with in_process_client(tmp_path / "tok.db", token="s3cret") as client:
        assert client.post("/api/jobs", json={"iterations": 1}).status_code == 401
        for path in ("/api/jobs", "/api/jobs/1", "/api/evaluations/1/trajectory", "/api/studies", "/api/view"):
            refused = client.get(path)
            assert refused.status_code == 401 and "Bearer" in refused.json()["detail"], path
        assert client.get("/api/health").status_code == 200
        assert client.get("/api/jobs", headers={"Authorization": "Bearer s3cret"}).json() == []
        assert client.get("/api/jobs", cookies={"driftlab_token": "s3cret"}).status_code == 200  # a page's cookie
        ok = client.post("/api/jobs", json={"iterations": 1}, headers={"Authorization": "Bearer s3cret"})
        assert ok.status_code == 201
        job_id = ok.json()["id"]
        assert client.delete(f"/api/jobs/{job_id}").status_code == 401
        assert client.delete(f"/api/jobs/{job_id}", headers={"Authorization": "Bearer s3cret"}).status_code == 204


def test_public_reads_open_the_reads_and_only_them(tmp_path):
    with in_process_client(tmp_path / "pub.db", token="s3cret", public_reads=True) as client:
        assert client.get("/api/jobs").json() == []
        assert client.post("/api/jobs", json={"iterations": 1}).status_code == 401
        schema = client.get("/openapi.json").json()
        assert "security" not in schema["paths"]["/api/jobs"]["get"]
        assert schema["paths"]["/api/jobs"]["post"]["security"] == [{"bearerToken": []}]


def test_the_docs_page_loads_only_pinned_files_with_their_integrity(api):
    page = api.get("/docs")
    assert page.status_code == 200
    external = re.findall(r'<(?:script|link)[^>]*(?:src|href)="https://[^"]*"[^>]*>', page.text)
    assert len(external) == 2  # the bundle and its stylesheet, nothing else leaves
    for tag in external:
        assert re.search(r'swagger-ui-dist@\d+\.\d+\.\d+/', tag), tag  # one version, not "@5"
        assert re.search(r'integrity="sha384-[A-Za-z0-9+/]{64}"', tag) and 'crossorigin="anonymous"' in tag, tag
    assert api.get("/redoc").status_code == 404  # ReDoc's bundle is not pinned: not served


def test_the_job_list_comes_in_pages_linked_to_the_next(api):
    ids = [api.post("/api/jobs", json={"name": f"p{i}", "iterations": 1}).json()["id"] for i in range(5)]
    seen, url = [], "/api/jobs?limit=2"
    while url:
        page = api.get(url)
        assert page.status_code == 200 and len(page.json()) <= 2
        seen += [job["id"] for job in page.json()]
        link = page.headers.get("link")
        url = re.fullmatch(r'<(.+)>; rel="next"', link)[1] if link else None
    assert seen == ids
    assert [j["id"] for j in api.get("/api/jobs").json()] == ids  # 100 a page by default
    assert api.get("/api/jobs", params={"limit": 0}).status_code == 422
