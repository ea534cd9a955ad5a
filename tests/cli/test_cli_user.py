"""`moi user`: "add" never overwrites a user that exists and the last enabled admin stays one (the users page's
rules), "change" does what it says, and
every change is a line of the users audit log the page writes, in the state directory."""

from __future__ import annotations

import io

from service.cli import main
from service.publish.web.auth import USERS_AUDIT_FILE, check_password, read_users


def _user(monkeypatch, *args: str, password: str | None = None) -> int:
    monkeypatch.setattr("sys.stdin", io.StringIO((password or "") + "\n"))
    return main(["user", *args] + (["--password-stdin"] if password is not None else []))


def test_add_refuses_an_existing_name_and_change_changes_it_each_audited(tmp_path, monkeypatch, capsys):
    users, state = tmp_path / "users.toml", tmp_path / "state"
    state.mkdir()
    common = ["--users-file", str(users), "--state-dir", str(state)]
    assert _user(monkeypatch, "add", "olga", "--role", "admin", *common, password="olga-password-1") == 0
    before = users.read_bytes()
    # the same name again: refused, said, the change command named, the file untouched (role and password kept)
    assert _user(monkeypatch, "add", "olga", "--role", "operator", *common, password="other-password-2") == 2
    err = capsys.readouterr().err
    assert "user 'olga' exists" in err and "moi user change olga" in err
    assert users.read_bytes() == before
    assert read_users(users)["olga"].role == "admin"
    # the last enabled admin is not demoted nor removed (the page's rule): refused, the file untouched
    assert _user(monkeypatch, "change", "olga", "--role", "quality", "--keep-password", *common) == 2
    assert "last enabled admin" in capsys.readouterr().err and users.read_bytes() == before
    assert _user(monkeypatch, "remove", "olga", *common) == 2 and users.read_bytes() == before
    assert _user(monkeypatch, "add", "ida", "--role", "admin", *common, password="ida-password-5") == 0
    # change: the role alone, then a new password
    assert _user(monkeypatch, "change", "olga", "--role", "quality", "--keep-password", *common) == 0
    assert read_users(users)["olga"].role == "quality"
    assert check_password("olga-password-1", read_users(users)["olga"].password)
    assert _user(monkeypatch, "change", "olga", *common, password="new-password-3") == 0
    assert check_password("new-password-3", read_users(users)["olga"].password)
    assert read_users(users)["olga"].role == "quality"
    # change of a name that is no user: refused, "add" named
    assert _user(monkeypatch, "change", "nobody", *common, password="some-password-4") == 2
    assert "moi user add nobody" in capsys.readouterr().err
    assert _user(monkeypatch, "remove", "olga", *common) == 0
    lines = (state / USERS_AUDIT_FILE).read_text(encoding="utf-8").splitlines()
    # one line per change, none for a refusal: when, who, what, whom, before → after; a new password said, not written
    assert [line.split("\t")[2:] for line in lines] == [
        ["added", "olga", "– → admin"], ["added", "ida", "– → admin"], ["changed", "olga", "admin → quality"],
        ["changed", "olga", "quality → quality; new password"], ["removed", "olga", "quality → –"]]
    assert all(line.split("\t")[1].startswith("cli") for line in lines)
    assert "password-" not in (state / USERS_AUDIT_FILE).read_text(encoding="utf-8")
