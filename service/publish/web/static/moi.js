// moi web page: plain JavaScript, no build step, nothing loaded from elsewhere.
"use strict";
var moi = (function () {
  function csrf() { var m = document.querySelector('meta[name="csrf-token"]'); return m ? m.content : ""; }
  // the states the appliance reports (service/states.py), served with the page: {name: {code, words, busy, capturing}}
  var STATES = (function () { var m = document.querySelector('meta[name="moi-states"]'); return m ? JSON.parse(m.content) : {}; })();
  // a release came to its end (its result published, or aborted): the page shows what the server now has
  function finished(s) { return s.previous === "PUBLISHING" || s.previous === "ABORTED"; }
  function busy(state) { return !!(STATES[state] && STATES[state].busy); }
  // the daemon's life the page was served in: a stream message of another means it restarted under the page
  var BOOT = (function () { var m = document.querySelector('meta[name="moi-boot"]'); return m ? m.content : ""; })();
  function restartedUnder(s) { return !!(s && s.boot && BOOT && s.boot !== BOOT); }
  function clock(d) { return d.toTimeString().slice(0, 8); }  // HH:MM:SS, local
  function $(id) { return document.getElementById(id); }
  function say(text, bad) { var m = $("message"); if (m) { m.textContent = text; m.className = "message" + (bad ? " bad" : ""); } }

  // POST an action with the session's CSRF token; the answer (or the refusal) is shown in words where given
  // (else in the page's message line); resolves to {ok, status, body}
  function act(url, body, where) {
    return fetch(url, {method: "POST", headers: {"X-CSRF-Token": csrf(), "Accept": "application/json"},
                       credentials: "same-origin", body: body})
      .then(function (r) { return r.json().then(function (body) { return {ok: r.ok, status: r.status, body: body}; }); })
      .then(function (r) {
        var tell = where || say;
        if (r.ok) {
          tell({trigger: "measurement requested", abort: "abort sent", part: "recipe / part ID set"}[r.body.command] || "");
        }
        else if (r.status === 409) { tell(r.body.error, true); }
        else if (r.status === 401) { tell("log in first (name and password at the top of the page)", true); }
        else { tell("refused (" + r.status + "): " + r.body.error, true); }
        return r;
      })
      .catch(function () {
        say("no answer from the appliance at " + clock(new Date()) + ": nothing was done", true);
        return {ok: false};
      });
  }

  // tick values of an axis from lo to hi: 1, 2 or 5 times a power of ten apart
  function ticks(lo, hi, n) {
    var span = hi - lo, raw = span / Math.max(1, n), p = Math.pow(10, Math.floor(Math.log10(raw))), step = p;
    [1, 2, 5, 10].forEach(function (m) { if (raw > m * p * 0.999) { step = m * p; } });
    if (raw > step) { step *= 2; }
    var out = [], v = Math.ceil(lo / step) * step;
    for (; v <= hi + step * 1e-9; v += step) { out.push(Math.abs(v) < step * 1e-9 ? 0 : v); }
    return out;
  }

  // the swing, drawn on a canvas as the samples arrive (angle in rad against t in s, labelled axes); when
  // the swing ends, the fit over it and the residual in a panel below
  function Swing(canvas) {
    this.c = canvas; this.t = []; this.a = []; this.tmax = 10; this.fit = null;
    var self = this;
    window.addEventListener("resize", function () { self.draw(); });
  }
  Swing.prototype.reset = function (tmax) { this.t = []; this.a = []; this.fit = null; if (tmax) { this.tmax = tmax; } this.draw(); };
  Swing.prototype.add = function (t, a) {
    for (var i = 0; i < t.length; i++) { this.t.push(t[i]); this.a.push(a[i]); }
    this.draw();
  };
  Swing.prototype.showFit = function (fit) { this.fit = fit; this.draw(); };
  Swing.prototype.panel = function (g, box, xs, ys, ylabel, tmax, amax, colour, dots) {
    var L = box.x, T = box.y, W = box.w, H = box.h;
    g.strokeStyle = "#999"; g.lineWidth = 1; g.strokeRect(L, T, W, H);
    g.fillStyle = "#333"; g.font = "12px sans-serif"; g.textAlign = "right"; g.textBaseline = "middle";
    var marks = H > 120 ? ticks(-amax, amax, 4) : [-0.8 * amax, 0, 0.8 * amax];  // a short panel: its range
    marks.forEach(function (v) {
      var y = T + H / 2 - v / amax * (H / 2 - 4);
      g.strokeStyle = "#eee"; g.beginPath(); g.moveTo(L, y); g.lineTo(L + W, y); g.stroke();
      g.fillText(v === 0 ? "0" : (Math.abs(amax) < 0.01 ? v.toExponential(1) : String(Number(v.toPrecision(2)))), L - 4, y);
    });
    g.save(); g.translate(12, T + H / 2); g.rotate(-Math.PI / 2); g.textAlign = "center"; g.fillText(ylabel, 0, 0); g.restore();
    g.strokeStyle = colour; g.lineWidth = dots ? 1 : 1.5; g.beginPath();
    for (var j = 0; j < xs.length; j++) {
      var x = L + xs[j] / tmax * W, y2 = T + H / 2 - ys[j] / amax * (H / 2 - 4);
      if (j) { g.lineTo(x, y2); } else { g.moveTo(x, y2); }
    }
    g.stroke();
  };
  Swing.prototype.draw = function () {
    var c = this.c, r = window.devicePixelRatio || 1, cw = c.clientWidth || 600, ch = c.clientHeight || 240;
    if (c.width !== Math.round(cw * r) || c.height !== Math.round(ch * r)) { c.width = Math.round(cw * r); c.height = Math.round(ch * r); }
    var g = c.getContext("2d"), n = this.t.length, fit = this.fit;
    g.setTransform(r, 0, 0, r, 0, 0); g.clearRect(0, 0, cw, ch);
    var L = 58, R = 10, B = 34, T = 8, W = cw - L - R, Htot = ch - T - B;
    var H = fit ? Htot * 0.68 : Htot, box = {x: L, y: T, w: W, h: H};
    var tmax = Math.max(this.tmax, n ? this.t[n - 1] : 0), amax = n ? 1e-6 : 0.2, i;
    for (i = 0; i < n; i++) { amax = Math.max(amax, Math.abs(this.a[i])); }
    amax *= 1.05;
    this.panel(g, box, this.t, this.a, "angle [rad]", tmax, amax, "#555", true);
    if (fit) {
      g.save(); g.beginPath(); g.rect(L, T, W, H); g.clip();
      this.panel(g, box, fit.t, fit.fitted, "angle [rad]", tmax, amax, "#c22", false);
      g.restore();
      var rmax = 1e-9;
      for (i = 0; i < fit.residual.length; i++) { rmax = Math.max(rmax, Math.abs(fit.residual[i])); }
      this.panel(g, {x: L, y: T + H + 8, w: W, h: Htot - H - 8}, fit.t, fit.residual, "residual [rad]", tmax, rmax * 1.1, "#26c", false);
    }
    // the time axis
    var yb = T + Htot;
    g.fillStyle = "#333"; g.textAlign = "center"; g.textBaseline = "top"; g.font = "12px sans-serif";
    ticks(0, tmax, Math.max(2, Math.floor(W / 70))).forEach(function (v) {
      var x = L + v / tmax * W;
      g.strokeStyle = "#999"; g.beginPath(); g.moveTo(x, yb); g.lineTo(x, yb + 4); g.stroke();
      g.fillText(String(Math.round(v * 100) / 100), x, yb + 5);
    });
    g.fillText("t [s]", L + W / 2, yb + 19);
    if (fit) {
      g.textAlign = "right"; g.textBaseline = "top"; g.fillStyle = "#c22";
      g.fillText("fit (red) over the samples (grey)", L + W - 4, T + 4);
    }
    this.c.setAttribute("data-drawn", String(n));
    this.c.setAttribute("data-fit", fit ? "1" : "0");
  };

  // replace the parts of the page a fragment of the server's holds (elements with data-part, by id)
  function swap(html) {
    var t = document.createElement("template");
    t.innerHTML = html;
    t.content.querySelectorAll("[data-part]").forEach(function (el) { var old = $(el.id); if (old) { old.replaceWith(el); } });
  }

  // --- every page: the live stream, the daemon's life, the appliance's reachability and a calibration block --
  var RESTARTED = "moi-restarted";  // what a restart took, kept over the reload that follows it
  // said once, on the page the new daemon served after a restart
  function tellRestart() {
    var told = window.sessionStorage.getItem(RESTARTED), n = $("restarted");
    if (!told || !n) { return; }
    window.sessionStorage.removeItem(RESTARTED);
    n.textContent = told; n.hidden = false; n.setAttribute("data-restarted", "1");
  }
  // the calibration's banner as the server now has it (every page but Home, whose banner is the part in hand's)
  // and the page's Measure refused with it
  function banner() {
    return fetch("/calibration/banner", {credentials: "same-origin"}).then(function (r) { return r.ok ? r.text() : null; })
      .then(function (html) {
        if (html === null) { return; }
        swap(html);
        var m = $("measure");
        if (!m) { return; }
        if ($("blocked")) { m.setAttribute("aria-disabled", "true"); m.setAttribute("aria-describedby", "blocked"); }
        else { m.removeAttribute("aria-disabled"); m.removeAttribute("aria-describedby"); }
      });
  }
  // the live stream every page keeps open: a message of another daemon's life reloads the page and says what was
  // lost; no stream for a while and no answer greys the page and disables its actions until the appliance answers
  // again; a calibration block that comes or goes is shown at once. ``hooks``: the page's own part of it
  // {state(s), tick(s), unreachable(), reachable(wasUnreachable), refused(refused), streamRefused(status)}
  function live(hooks) {
    var es = null, lostAt = null, offlineTimer = null, seen = null, refused = !!$("blocked");
    tellRestart();
    // the daemon restarted under the page: what it held (the part in hand, the session) is gone; said, and the
    // page served again by the new daemon (nothing the old one showed is kept as current)
    function restarted() {
      var text = "The appliance restarted (seen at " + clock(new Date()) + ")";
      var rn = seen && seen.release_next, pid = seen && seen.part_id;
      if (pid && rn && rn.k > 1) {
        text += ": the part in hand " + pid + " (release " + (rn.k - 1) + " of " + rn.of + " done) was not finished; set its part ID again and measure it from release 1";
      } else if (pid) { text += ": the part ID " + pid + " is no longer set"; }
      if ($("who")) { text += "; you were logged out: log in again"; }
      window.sessionStorage.setItem(RESTARTED, text + ".");
      if (es) { es.close(); }
      window.location.reload();
    }
    // no stream for a while: asked whether the appliance answers at all (a stream refused for want of a slot is
    // not an outage); a hung request counts as no answer after 2 s
    function offline() {
      offlineTimer = null;
      var ask = new AbortController(), limit = setTimeout(function () { ask.abort(); }, 2000);
      fetch("/api/state", {credentials: "same-origin", signal: ask.signal}).then(function (r) {
        clearTimeout(limit);
        if (lostAt && hooks.streamRefused) { hooks.streamRefused(r.status); }
      }, function () { clearTimeout(limit); if (lostAt) { unreachable(); } });
    }
    // the appliance is unreachable: the page greys, every action on it is disabled (each needs the appliance),
    // the time said
    function unreachable() {
      document.body.setAttribute("data-offline", "1");
      document.querySelectorAll("button, input[type=submit]").forEach(function (b) {
        if (!b.disabled) { b.disabled = true; b.setAttribute("data-offline-disabled", "1"); }
      });
      var o = $("offline");
      o.textContent = "appliance not reachable since " + clock(lostAt) + ": " + (hooks.lostWords ||
        "what this page shows is as it was then, and nothing can be done on it until it answers");
      o.hidden = false;
      if (hooks.unreachable) { hooks.unreachable(); }
    }
    function online() {
      if (offlineTimer) { clearTimeout(offlineTimer); offlineTimer = null; }
      if (!lostAt) { return; }
      var was = document.body.getAttribute("data-offline") === "1";
      lostAt = null; document.body.removeAttribute("data-offline"); $("offline").hidden = true;
      document.querySelectorAll("[data-offline-disabled]").forEach(function (b) {
        b.disabled = false; b.removeAttribute("data-offline-disabled");
      });
      if (hooks.reachable) { hooks.reachable(was); }
    }
    // what every page does with a message; false: the page is being served again
    function shared(s) {
      if (restartedUnder(s)) { restarted(); return false; }
      online();
      if (s.release_next !== undefined) { seen = s; }
      if (s.measure_refused !== undefined && !!s.measure_refused !== refused) {
        refused = !!s.measure_refused;
        (hooks.refused || banner)(refused);
      }
      return true;
    }
    function connect() {
      es = new EventSource(hooks.tick ? "/events" : "/events?samples=no");  // the samples only where the swing is drawn
      es.addEventListener("state", function (e) { var s = JSON.parse(e.data); if (shared(s) && hooks.state) { hooks.state(s); } });
      es.addEventListener("tick", function (e) {
        var s = JSON.parse(e.data);
        document.body.setAttribute("data-live", "1");  // connected: every transition from now on is shown
        if (shared(s) && hooks.tick) { hooks.tick(s); }
      });
      es.onerror = function () {
        // a stream also ends at its lifetime and is opened again within a second: unreachable only after a grace
        if (!lostAt) { lostAt = new Date(); offlineTimer = setTimeout(offline, 2500); }
        if (es.readyState === EventSource.CLOSED) { setTimeout(connect, 2000); }  // refused: the browser gives up
      };
    }
    // a page left (or kept by the browser for "back") gives its stream back at once: the appliance's slots for
    // streams are few, and one held by a page nobody sees refuses the next page its own
    window.addEventListener("pagehide", function () { if (es) { es.close(); es = null; } });
    window.addEventListener("pageshow", function (e) { if (e.persisted && !es) { connect(); } });
    connect();
    return {unreachable: function () { return document.body.getAttribute("data-offline") === "1"; }};
  }
  // a page with nothing live of its own: the shared part alone
  function page() { live({}); }

  function home() {
    var swing = new Swing($("swing")), mid = null, measure = $("measure"), lastState = null, seen = null;
    var view = null, pressing = false;
    function refresh() {
      return fetch("/home/summary", {credentials: "same-origin"}).then(function (r) { return r.ok ? r.text() : null; })
        .then(function (html) { if (html) { swap(html); syncMeasure(); } });
    }
    // the Measure button carries what the server says about the part in hand (refused, or a part to repeat) and
    // the state: greyed in FAULT (the daemon refuses it, saying why), busy and disabled while a measurement runs
    function syncMeasure() {
      var b = $("blocked"), st = $("state").textContent, running = busy(st);
      if (b || st === "FAULT") { measure.setAttribute("aria-disabled", "true"); } else { measure.removeAttribute("aria-disabled"); }
      measure.setAttribute("aria-busy", running ? "true" : "false");
      if (!view || !view.unreachable()) { measure.disabled = running; }  // while unreachable, the shared part decides
      var now = $("now");
      measure.setAttribute("data-repeat", now ? now.getAttribute("data-repeat") || "" : "");
    }
    // the part in hand while it is measured: neutral, never the previous part's verdict
    function measuring(s) {
      var now = $("now");
      if (!now || now.getAttribute("data-measuring") === "1") { return; }
      // a tick says the part and the release being measured; a transition or the press alone: the last tick's
      if (!s || s.release_next === undefined) { s = seen; }
      var pid = (s && s.part_id) || ($("part-id").textContent !== "–" ? $("part-id").textContent : "(no part ID)");
      var rn = s && s.release_next;
      now.className = "now now-measuring"; now.setAttribute("data-measuring", "1");
      now.innerHTML = "";
      var p = document.createElement("p"); p.className = "now-line"; p.id = "now-line";
      var w = document.createElement("span"); w.className = "now-word"; w.textContent = "MEASURING";
      p.appendChild(w);
      p.appendChild(document.createTextNode(" " + pid + (rn ? " · release " + rn.k + " of " + rn.of : "")));
      var n = document.createElement("p"); n.className = "next"; n.id = "next-step";
      n.textContent = "Do not touch the part until the result is shown.";
      now.appendChild(p); now.appendChild(n);
    }
    measure.addEventListener("click", function () {
      if (pressing || view.unreachable()) { return; }  // one press at a time; none while the appliance is unreachable
      var b = $("blocked");
      if (measure.getAttribute("aria-disabled") === "true" && b) { say(b.textContent, true); return; }
      var rep = measure.getAttribute("data-repeat");
      if (rep && !window.confirm("Part " + rep + " is complete. Measure it again as a new part with the same ID?")) {
        say("not measured: enter the next part's ID first"); var pb = $("part-box"); if (pb) { pb.open = true; } return;
      }
      pressing = true;
      act("/api/measure").then(function (r) { pressing = false; if (r.ok) { measuring(null); } });
    });
    $("abort").addEventListener("click", function () {
      act("/api/abort");  // "aborted" is said when the sequencer says so (ABORTED), not on the request alone
    });
    function show(s) {
      if (s.release_next !== undefined) { seen = s; }
      var el = $("state");
      el.textContent = s.state; el.className = "state state-" + s.state;
      var wd = $("words");  // a FAULT in the words of the one reading it: who acknowledges it
      wd.textContent = (s.state === "FAULT" && wd.getAttribute("data-fault-words")) || s.words || "";
      syncMeasure();
      var f = $("fault");
      if (s.state === "FAULT" && s.fault) { f.textContent = s.fault; f.hidden = false; } else { f.hidden = true; }
      if (s.recipe !== undefined) { $("recipe").textContent = s.recipe ? s.recipe.number + " " + s.recipe.name : "–"; }
      if (s.part_id !== undefined) {
        var shown = $("part-id").textContent, pid = s.part_id || "–";
        $("part-id").textContent = pid;
        if (shown !== pid && !busy(s.state)) { refresh(); }  // another part in hand: ready, not the last verdict
      }
      var rk = $("release-k");
      if (rk && s.release_next !== undefined) {
        rk.textContent = s.release_next ? (busy(s.state) ? "measuring release " : "next: release ") + s.release_next.k + " of " + s.release_next.of : "–";
      }
      if (busy(s.state) && s.state !== "ABORTED") { measuring(s); }
      var box = $("progress-box"), bar = $("progress-bar"), txt = $("progress-text");
      if (s.state === "CAPTURING" && s.elapsed !== undefined) {
        box.hidden = false; bar.style.width = Math.min(100, 100 * s.elapsed / s.capture_duration) + "%";
        txt.textContent = s.elapsed.toFixed(1) + " s captured, " + s.remaining.toFixed(1) + " s to go";
      } else if (s.state === "IDENTIFYING" && s.identifying_for !== undefined) {
        box.hidden = false;
        var typical = s.identify_typical || 2.0, frac = Math.min(0.95, s.identifying_for / typical);
        bar.style.width = (100 * frac) + "%";
        txt.textContent = "identifying for " + s.identifying_for.toFixed(1) + " s" +
          (s.identify_typical ? " (the last one took " + s.identify_typical.toFixed(1) + " s)" : "");
      } else { box.hidden = true; }
    }
    function logState(s) {
      var li = document.createElement("li");
      li.textContent = s.state + " — " + (s.reason || "");
      li.setAttribute("data-state", s.state);
      $("log").appendChild(li);
      if (s.state === "ABORTED") { say("aborted: this release is not counted; Measure measures it again"); }
      else if (s.state === "FAULT") { say(""); }  // answered now
      else if (s.state === "IDLE" && lastState !== "ABORTED") { say(""); }
      // a FAULT, and its acknowledgement: the part in hand as the server now has it (never READY under FAULT)
      var fault = function (name) { return name === "FAULT"; };
      if (fault(s.state) || (s.state === "IDLE" && (fault(lastState) || fault(s.previous)))) { refresh(); }
      lastState = s.state;
      if (s.state === "IDLE" && finished(s)) {
        var id = s.measurement_id;
        // the part in hand, the counters and the last parts as the server now has them
        refresh();
        if (s.previous === "PUBLISHING") {
          fetch("/results/" + id + "/fit.json", {headers: {"Accept": "application/json"}})
            .then(function (r) { return r.ok ? r.json() : null; })
            .then(function (fit) { if (fit && id === mid) { swing.showFit(fit); } });
        }
      }
    }
    var pf = $("part-form");
    if (pf) {
      var err = $("part-id-error"), input = $("part-id-input");
      function fieldError(text) {
        err.textContent = text || "";
        if (text) { input.setAttribute("aria-invalid", "true"); } else { input.removeAttribute("aria-invalid"); }
      }
      pf.addEventListener("submit", function (e) {
        e.preventDefault();
        var fd = new FormData(pf), pid = String(fd.get("part_id") || "");
        if (!pid) { fd.delete("part_id"); }
        else {
          // a scan is never cut to fit (a wrong serial in the record): refused, saying what is wrong with it
          var most = Number(input.getAttribute("data-max-length")), bad = pid.match(/[^ -~]/), n = pid.trim().length;
          if (bad) {
            fieldError("\u201c" + bad[0] + "\u201d (character " + (pid.indexOf(bad[0]) + 1) +
                       ") is refused: a part ID holds printable ASCII only"); input.focus(); return;
          }
          if (n > most) {
            fieldError(n + " characters: a part ID holds at most " + most + " (nothing was cut: check the scan)");
            input.focus(); return;
          }
        }
        if (!fd.get("recipe")) { fd.delete("recipe"); }
        act(pf.getAttribute("data-action"), new URLSearchParams(fd), function (text, bad) {
          if (bad) { fieldError(text); input.focus(); } else { fieldError(""); say(text); }
        }).then(function (r) {
          var sel = $("recipe-select");
          if (sel) { sel.value = ""; }  // a refused recipe is not sent again with the next part ID
          if (r.ok) { input.value = ""; $("part-box").open = false; }
        });
      });
    }
    view = live({
      state: function (s) { logState(s); show(s); },
      tick: function (s) {
        show(s);
        if (s.samples) {
          if (s.reset || s.measurement_id !== mid) { mid = s.measurement_id; swing.reset(s.capture_duration + (s.pre_trigger || 0)); }
          swing.add(s.samples.t, s.samples.angle);
        }
      },
      lostWords: "nothing can be measured until it answers",
      unreachable: function () {
        var el = $("state"); el.textContent = "NO CONNECTION"; el.className = "state state-unreachable"; $("words").textContent = "";
        // the card says so too: not "press Measure" while nothing can be measured (the server's card is back on
        // reconnection)
        var now = $("now");
        if (now) {
          now.className = "now now-unreachable"; now.removeAttribute("data-measuring"); now.innerHTML = "";
          var p = document.createElement("p"); p.className = "now-line"; p.id = "now-line";
          var w = document.createElement("span"); w.className = "now-word"; w.textContent = "NOT REACHABLE"; p.appendChild(w);
          var n = document.createElement("p"); n.className = "next"; n.id = "next-step";
          n.textContent = "The appliance is not reachable: nothing can be measured until it answers (since " + clock(new Date()) + ").";
          now.appendChild(p); now.appendChild(n);
        }
      },
      reachable: function (was) { if (was) { refresh(); } },  // what changed meanwhile
      refused: function () { refresh(); },  // the banner and Measure as the server now has them (the part in hand's)
      streamRefused: function (status) { $("words").textContent = "the live view is refused for now (" + status + "); asking again"; }
    });
  }

  function setup() {
    live({});
    var b = $("snapshot-button");
    if (b) {
      b.addEventListener("click", function () {
        var img = $("snapshot");
        fetch("/setup/snapshot.png?ts=" + Date.now()).then(function (r) {
          if (!r.ok) { return r.text().then(function (t) { say("snapshot refused (" + r.status + ")", true); }); }
          return r.blob().then(function (blob) { img.src = URL.createObjectURL(blob); img.hidden = false; say(""); });
        });
      });
    }
    var a = $("angle-button"), timer = null;
    function read() {
      fetch("/api/angle", {headers: {"Accept": "application/json"}}).then(function (r) { return r.json().then(function (j) {
        if (r.ok) { $("angle").textContent = j.angle_rad.toFixed(5) + " rad (" + (j.angle_rad * 180 / Math.PI).toFixed(3) + "°)"; say(""); }
        else { say(j.error, true); }
      }); });
    }
    if (a) {
      a.addEventListener("click", read);
      $("angle-live").addEventListener("change", function (e) {
        if (e.target.checked) { timer = setInterval(read, 500); } else { clearInterval(timer); }
      });
    }
  }
  // the tensor set's page: Measure and Abort, and the page as the appliance has it after each release
  function tensorSet() {
    var m = $("measure"), a = $("abort");
    if (m) {
      m.addEventListener("click", function () {
        var b = $("blocked");
        if (m.getAttribute("aria-disabled") === "true" && b) { say(b.textContent, true); return; }
        act("/api/measure");
      });
    }
    if (a) { a.addEventListener("click", function () { act("/api/abort"); }); }
    live({state: function (s) {
      if (busy(s.state)) { say(s.state + ": " + (s.words || "")); }
      if (s.state === "IDLE" && finished(s)) { window.location.reload(); }
    }});
  }
  // the recipes page's edit forms: the inertias are read in the display unit chosen in the same form, so their
  // labels follow the select at once; a number left as the form showed it is converted with it (its value kept),
  // a number typed is read in the unit chosen; the note says what will be saved, in both units, before Save
  function recipes() {
    document.querySelectorAll("form.recipe-form").forEach(function (form) {
      var sel = form.querySelector("select[name=display_unit]"), note = form.querySelector(".recipe-unit-note");
      if (!sel) { return; }
      var opened = form.getAttribute("data-unit"), was = opened;
      function unitOf() { return sel.value || form.getAttribute("data-default-unit"); }
      var factors = JSON.parse(sel.getAttribute("data-factors") || "{}");  // each unit per kg·m²
      function factor(u) { return factors[u] || null; }
      function number(text) { var t = String(text).trim().replace(",", "."); return t && isFinite(Number(t)) ? Number(t) : null; }
      function inertias() {
        return Array.prototype.map.call(form.querySelectorAll("label[data-inertia]"), function (l) {
          return {label: l, name: l.getAttribute("data-inertia"), input: $(l.getAttribute("for"))};
        }).filter(function (f) { return f.input; });
      }
      function tell() {
        var u = unitOf(), fu = factor(u), said = [];
        inertias().forEach(function (f) {
          var v = number(f.input.value);
          if (v === null) { return; }
          said.push(f.name + " " + f.input.value.trim() + " " + u + (fu && u !== "kg·m²" ? " (= " + Number((v / fu).toPrecision(6)) + " kg·m²)" : ""));
        });
        note.textContent = (u !== opened ? "display unit " + opened + " → " + u + ": " : "") +
          (said.length ? "saved as " + said.join(", ") : "nominal and tolerance are read in " + u);
        note.setAttribute("data-unit", u);
      }
      sel.addEventListener("change", function () {
        var u = unitOf(), from = factor(was), to = factor(u);
        inertias().forEach(function (f) {
          f.label.textContent = f.name + " (" + u + ")";
          var v = number(f.input.value);
          // left as the form showed it (in the unit it was shown in): the same value, in the new unit
          if (v !== null && from && to && f.input.value === f.input.getAttribute("data-shown")) {
            f.input.value = String(Number((v * to / from).toPrecision(12)));
            f.input.setAttribute("data-shown", f.input.value);
          }
        });
        was = u; tell();
      });
      inertias().forEach(function (f) {
        f.input.setAttribute("data-shown", f.input.value);
        f.input.addEventListener("input", tell);
      });
      tell();
    });
  }
  return {home: home, setup: setup, tensorSet: tensorSet, page: page, act: act, states: STATES, recipes: recipes};
})();
