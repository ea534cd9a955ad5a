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
    assert c.request("/login", {"user": "olga", "token": "olga-password-1", "csrf": c.csrf()})[0] == 403
    assert c.request("/login", {"user": "olga", "token": "not-her-password", "csrf": c.csrf()})[0] == 401
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


@pytest.fixture
def recipe_app(appliance_factory, tmp_path):
    from service.publish.web.auth import User, hash_password, save_users

    users = tmp_path / "users.toml"
    save_users(users, {n: User(n, "quality", hash_password(f"{n}-password-1")) for n in ("quinn", "rita")})
    d = tmp_path / "recipes"
    d.mkdir()
    (d / "g.toml").write_text('[recipe]\nname = "rotor-g"\nnumber = 5\nnominal = 0.0125  # kg·m²\n'
                              'tolerance = 0.0002\ndisplay_unit = "g·cm²"\n')
    app = appliance_factory(appliance_doc(tmp_path / "state", web={"enabled": True, "users_file": str(users)},
                                          recipes={"directory": str(d)})).app
    return app, d / "g.toml", tmp_path / "state" / "recipe-audit.log"


def _quality(app, name: str) -> tuple[Client, str]:
    c = Client(app.web.url)
    c.request("/login", {"user": name, "token": f"{name}-password-1", "csrf": c.csrf()})
    return c, c.request("/recipes")[2].decode()


def _form(page: str) -> dict[str, str]:
    """The recipe form's fields as the page fills them (text inputs and the selected option)."""
    form = page.split('id="edit-5"')[1].split("</form>")[0]
    fields = dict(re.findall(r'<input type="(?:hidden|text)" name="(\w+)"[^>]*?value="([^"]*)"', form))
    for name, options in re.findall(r'<select name="(\w+)"[^>]*>(.*?)</select>', form, re.S):
        chosen = re.search(r'<option(?: value="([^"]*)")? selected>([^<]*)<', options)
        assert chosen is not None, options
        fields[name] = chosen[1] if chosen[1] is not None else chosen[2]
    return fields


def test_a_recipe_is_edited_in_its_own_unit_with_a_decimal_comma_and_every_error_said_by_its_label(recipe_app):
    app, path, audit = recipe_app
    quinn, page = _quality(app, "quinn")
    form = _form(page)
    # the nominal and the tolerance in the recipe's g·cm², the unit chosen from a list
    assert form["nominal"] == "125000" and form["tolerance"] == "2000" and form["display_unit"] == "g·cm²"
    assert "nominal (g·cm²)" in page and "tolerance (g·cm²)" in page and "nominal (kg·m²)" not in page
    assert re.search(r'<select name="display_unit"[^>]*>.*<option>lb·in²</option>', page, re.S)
    # every refused value, by its label, without the server's path or the file's key syntax
    status, _, body = quinn.request("/recipes", {**form, "nominal": "abc", "releases": "0",
                                                 "display_decimals": "1,5,0"})
    answer = body.decode()
    errors = answer.split('id="recipe-error"')[1].split("</ul>")[0]
    assert status == 400 and errors.count("<li>") == 3, errors
    assert "<b>nominal (g·cm²)</b>: expected a number" in errors and "<b>releases</b>: expected at least 1" in errors
    assert "<b>display decimals</b>: expected a number with one decimal separator" in errors
    assert str(path.parent) not in errors and "[recipe]" not in errors
    assert "releases" not in path.read_text()
    # a decimal comma, in g·cm²: the file gets kg·m²; what was not touched is not rewritten
    status, _, body = quinn.request("/recipes", {**form, "nominal": "130000,5"})
    text = path.read_text()
    assert status == 200 and "nominal = 0.01300005  # kg·m²" in text and "tolerance = 0.0002\n" in text
    assert 'value="130000.5"' in body.decode()
    assert audit.read_text().splitlines()[-1].split("\t")[1:] == ["web:quinn", "rotor-g", "g.toml",
                                                                  "nominal: 0.0125 → 0.01300005"]
    # a cross-key refusal of the loader is said by its label too
    status, _, body = quinn.request("/recipes", {**_form(quinn.request("/recipes")[2].decode()),
                                                 "tolerance": "200000"})
    assert status == 400 and "<b>tolerance (g·cm²)</b>: expected less than the nominal" in body.decode()


def test_two_quality_engineers_editing_one_recipe_the_later_is_refused_and_audited(recipe_app):
    app, path, audit = recipe_app
    quinn, page_q = _quality(app, "quinn")
    rita, page_r = _quality(app, "rita")
    assert quinn.request("/recipes", {**_form(page_q), "releases": "3"})[0] == 200
    status, _, body = rita.request("/recipes", {**_form(page_r), "nominal": "126000"})
    answer = body.decode()
    assert status == 409 and "changed since you opened it" in answer and "nothing was saved" in answer
    assert "releases = 3" in path.read_text() and "nominal = 0.0125" in path.read_text()
    assert _form(answer)["releases"] == "3"  # the recipe as it is now
    lines = [line.split("\t")[1:] for line in audit.read_text().splitlines()]
    assert lines == [["web:quinn", "rotor-g", "g.toml", "releases: – → 3"],
                     ["web:rita", "rotor-g", "g.toml",
                      "refused: the file changed since the form was opened → nothing written"]]
    assert rita.request("/recipes", {**_form(answer), "nominal": "126000"})[0] == 200
    assert "nominal = 0.0126" in path.read_text() and "releases = 3" in path.read_text()


def test_a_part_id_too_long_or_with_a_refused_character_is_refused_saying_which_never_cut(appliance_factory,
                                                                                           tmp_path):
    d = tmp_path / "recipes"
    d.mkdir()
    (d / "a.toml").write_text('[recipe]\nname = "rotor-a"\nnumber = 3\nnominal = 0.0125\ntolerance_percent = 2.0\n')
    app = appliance_factory(appliance_doc(tmp_path / "state", web={"enabled": True},
                                          recipes={"directory": str(d)})).app
    bearer = {"Authorization": f"Bearer {Path(app.web.token_file).read_text().strip()}"}
    c = Client(app.web.url)
    home = c.request("/")[2].decode()
    found = re.search(r'<input[^>]*id="part-id-input"[^>]*>', home)
    assert found is not None
    field = found[0]
    assert "maxlength" not in field and 'data-max-length="20"' in field  # the browser never cuts a scan
    scanned = "SN-2026-11-28-LINE3-0000123456"
    status, doc = c.json("/api/part", data={"part_id": scanned + "X"}, headers=bearer)
    assert status == 400 and "part ID must be at most 20 characters, got 31" in doc["error"]
    status, doc = c.json("/api/part", data={"part_id": "SN 1004 ü"}, headers=bearer)
    assert status == 400 and "'ü' (character 9) refused" in doc["error"] and "at most" not in doc["error"]
    assert c.json("/api/part", data={"part_id": scanned[:20]}, headers=bearer)[0] == 202


@pytest.mark.skipif(__import__("shutil").which("node") is None, reason="no node to run the page's script")
def test_the_page_s_part_id_check_says_the_length_or_the_character_at_fault(tmp_path):
    """The submit handler's check, run under node on a stub page: the length said for a long scan, the refused
    character (not the length) for "SN 1004 ü", nothing sent in either case."""
    import subprocess

    script = (Path(__file__).parents[4] / "service/publish/web/static/moi.js").read_text()
    body = script.split('pf.addEventListener("submit", function (e) {')[1].split("if (!fd.get(\"recipe\"))")[0]
    probe = ("var out = [], current = '', e = {preventDefault: function () {}}, pf = {};\n"
             "function fieldError(t) { out.push(t); }\n"
             "function FormData() { return {get: function () { return current; }, delete: function () {}}; }\n"
             "var input = {getAttribute: function () { return '20'; }, focus: function () {}};\n"
             "function check(pid) { current = pid; (function () {\n" + body + "\n out.push('sent'); })(); }\n"
             "check('SN-2026-11-28-LINE3-0000123456X'); check('SN 1004 \\u00fc'); check('SN-7');\n"
             "console.log(JSON.stringify(out));")
    (tmp_path / "probe.js").write_text(probe, encoding="utf-8")
    said = __import__("json").loads(subprocess.run(["node", str(tmp_path / "probe.js")], capture_output=True,
                                                   text=True, check=True).stdout)
    assert said[0] == "31 characters: a part ID holds at most 20 (nothing was cut: check the scan)"
    assert said[1] == "\u201cü\u201d (character 9) is refused: a part ID holds printable ASCII only"
    assert said[2:] == ["sent"]


def test_a_lockout_outlives_a_restart_until_its_end_and_an_enable_lifts_it_for_good(tmp_path):
    """The lockouts are kept in the state directory with their wall-clock end: a guard made again (the daemon
    restarted) still refuses the locked name from that address; the end and an admin's enable both hold."""
    from service.publish.web.auth import LOCKOUT_TIME, LOCKOUT_WRONG, SOURCE_WRONG, Guard, User, hash_password

    users = {"olga": User("olga", "operator", hash_password("olga-password-1"))}
    kept = tmp_path / "web-lockouts.json"
    mono, wall = [100.0], [1_800_000_000.0]

    def guard() -> Guard:
        return Guard("t" * 24, clock=lambda: mono[0], users=users, lockout_file=kept, wall=lambda: wall[0])

    first = guard()
    for _ in range(LOCKOUT_WRONG):
        first.login("wrong", "olga", "192.0.2.66")
    for i in range(SOURCE_WRONG):  # a guesser going through the names, a few tries each
        first.login("wrong", f"name-{i // (LOCKOUT_WRONG - 1)}", "192.0.2.77")
    mono[0], wall[0] = 5.0, wall[0] + 60  # restarted a minute later: a new monotonic clock
    again = guard()
    assert again.throttled("olga", "192.0.2.66") == pytest.approx(LOCKOUT_TIME - 60)
    assert again.throttled("olga", "192.0.2.77") == pytest.approx(LOCKOUT_TIME - 60)  # the address's, too
    assert again.login("olga-password-1", "olga", "192.0.2.66") is None
    assert again.login("olga-password-1", "olga", "192.0.2.10") is not None  # elsewhere, in at once
    again.unlock("olga")
    assert guard().throttled("olga", "192.0.2.66") == 0  # the enable is kept too
    wall[0] += LOCKOUT_TIME
    assert guard().throttled("olga", "192.0.2.77") == 0  # and every lockout ends by itself
    kept.write_text("{not json")
    assert guard().throttled("olga", "192.0.2.66") == 0  # a damaged file is said in the log, not a crash
