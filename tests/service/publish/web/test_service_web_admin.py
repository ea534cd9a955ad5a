"""The admin's and the quality engineer's pages over HTTP: users added, changed and removed only as said, the
last admin kept, two admins at once told apart by the page's version, every change audited; a lockout said as
one, with its end."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.service.conftest import appliance_doc
from tests.service.publish.web.test_service_web import Client


def _csrf(page: str) -> str:
    return page.split('name="csrf-token" content="')[1].split('"')[0]


def _version(page: str) -> str:
    return page.split('name="version" value="')[1].split('"')[0]


@pytest.fixture
def users_app(appliance_factory, tmp_path, monkeypatch):
    from service.publish.web import auth
    from service.publish.web.auth import User, hash_password, save_users

    monkeypatch.setattr(auth, "GUESS_DELAY", 0.01)
    users = tmp_path / "users.toml"
    save_users(users, {"root": User("root", "admin", hash_password("root-password-1")),
                       "olga": User("olga", "operator", hash_password("olga-password-1"))})
    app = appliance_factory(appliance_doc(tmp_path / "state", web={"enabled": True, "users_file": str(users)})).app
    return app, users, tmp_path / "state"


def _admin(app) -> tuple[Client, str]:
    c = Client(app.web.url)
    c.request("/login", {"token": Path(app.web.token_file).read_text().strip(), "csrf": c.csrf()})
    return c, c.request("/users")[2].decode()


def test_users_are_added_changed_and_removed_only_as_said_and_every_change_is_audited(users_app):
    from service.publish.web.auth import check_password, read_users

    app, users, state = users_app
    admin, page = _admin(app)
    csrf = _csrf(page)
    before = read_users(users)["olga"]

    def post(**form) -> tuple[int, str]:
        status, _, body = admin.request("/users", {"csrf": csrf, "version": _version(admin.request("/users")[2]
                                                                                        .decode()), **form})
        return status, body.decode()

    # "add" with a name that exists is refused, the user untouched
    status, answer = post(action="add", name="olga", role="admin", password="taken-over-1")
    assert status == 400 and "user &#39;olga&#39; exists" in answer and "change" in answer
    assert read_users(users)["olga"] == before
    # "change" sets the role; an empty password keeps the old one
    status, answer = post(action="change", name="olga", role="quality", password="")
    assert status == 200 and "<td>olga</td><td>quality</td>" in answer
    assert read_users(users)["olga"].password == before.password
    status, _ = post(action="change", name="olga", role="quality", password="olga-password-2")
    assert status == 200 and check_password("olga-password-2", read_users(users)["olga"].password)
    assert post(action="change", name="nobody", role="quality", password="")[0] == 400
    # the one admin is never demoted, disabled or removed
    for form in ({"action": "change", "name": "root", "role": "operator"}, {"action": "disable", "name": "root"},
                 {"action": "remove", "name": "root", "confirm": "root"}):
        status, answer = post(**form)
        assert status == 400 and "the last enabled admin cannot be" in answer, form
    assert read_users(users)["root"].role == "admin" and not read_users(users)["root"].disabled
    # a removal needs its confirmation, offered beside the button
    assert 'name="confirm" value="olga" required' in admin.request("/users")[2].decode()
    status, answer = post(action="remove", name="olga")
    assert status == 400 and "needs its confirmation" in answer and "olga" in read_users(users)
    assert post(action="remove", name="olga", confirm="olga")[0] == 200 and "olga" not in read_users(users)

    audit = (state / "users-audit.log").read_text().splitlines()
    assert [line.split("\t")[1:] for line in audit] == [
        ["web", "changed", "olga", "operator → quality"],
        ["web", "changed", "olga", "quality → quality; new password"],
        ["web", "removed", "olga", "quality → –"]]
    assert re.match(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d", audit[0])
    assert "olga-password-2" not in (state / "users-audit.log").read_text()


def test_two_admins_at_once_the_later_form_is_refused_with_the_users_as_they_are(users_app):
    from service.publish.web.auth import User, hash_password, read_users, save_users

    app, users, state = users_app
    save_users(users, {**read_users(users), "ada": User("ada", "admin", hash_password("ada-password-1"))})
    app.web.guard.users = read_users(users)
    first, page_1 = _admin(app)
    second, page_2 = _admin(app)
    assert _version(page_1) == _version(page_2)
    status, _, _ = first.request("/users", {"action": "disable", "name": "olga", "version": _version(page_1),
                                            "csrf": _csrf(page_1)})
    assert status == 200 and read_users(users)["olga"].disabled
    # the second admin's page was opened before: its change would undo the first one's without a word
    status, _, body = second.request("/users", {"action": "change", "name": "olga", "role": "quality",
                                                "version": _version(page_2), "csrf": _csrf(page_2)})
    answer = body.decode()
    assert status == 409 and "changed since you opened" in answer
    assert re.search(r'id="user-olga".*?class="login-state">disabled<', answer, re.S)  # the state now
    assert read_users(users)["olga"] == User("olga", "operator", read_users(users)["olga"].password, True)
    c = Client(app.web.url)
    assert c.request("/login", {"user": "olga", "token": "olga-password-1", "csrf": c.csrf()})[0] == 401
    # on the page as it is now, the change goes through
    status, _, _ = second.request("/users", {"action": "change", "name": "olga", "role": "quality",
                                             "version": _version(answer), "csrf": _csrf(page_2)})
    assert status == 200 and read_users(users)["olga"].role == "quality"
    assert len((state / "users-audit.log").read_text().splitlines()) == 2


def test_a_login_locked_out_is_told_so_with_the_time_it_ends(users_app):
    from service.publish.web.auth import LOCKOUT_WRONG

    app, _, _ = users_app
    c = Client(app.web.url)
    for i in range(LOCKOUT_WRONG):
        status, _, body = c.request("/login", {"user": "olga", "token": "wrong-password", "csrf": c.csrf()})
        text = body.decode()
        assert status == 401 and "wrong user name or password" in text
        assert ("locked out" in text) == (i == LOCKOUT_WRONG - 1), i  # the try that locks it says so
    assert re.search(r"paused until \d{4}-\d\d-\d\d \d\d:\d\d:\d\d \(1[0-5] more min\)", text)
    status, _, body = c.request("/login", {"user": "olga", "token": "olga-password-1", "csrf": c.csrf()})
    assert status == 429 and "locked out" in body.decode() and "paused until" in body.decode()
