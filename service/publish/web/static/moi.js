// moi web page: plain JavaScript, no build step, nothing loaded from elsewhere.
"use strict";
var moi = (function () {
  function csrf() { var m = document.querySelector('meta[name="csrf-token"]'); return m ? m.content : ""; }
  function $(id) { return document.getElementById(id); }
  function say(text, bad) { var m = $("message"); if (m) { m.textContent = text; m.className = "message" + (bad ? " bad" : ""); } }

  // POST an action with the session's CSRF token; the answer (or the refusal) is shown in words
  function act(url, body) {
    return fetch(url, {method: "POST", headers: {"X-CSRF-Token": csrf(), "Accept": "application/json"},
                       credentials: "same-origin", body: body})
      .then(function (r) { return r.json().then(function (body) { return {ok: r.ok, status: r.status, body: body}; }); })
      .then(function (r) {
        if (r.ok) {
          say({trigger: "measurement requested", abort: "abort / acknowledge sent", part: "recipe / part ID set"}[r.body.command]);
        }
        else { say("refused (" + r.status + "): " + r.body.error, true); }
      })
      .catch(function (e) { say("no answer from the appliance: " + e, true); });
  }

  // the swing, drawn on a canvas as the samples arrive
  function Swing(canvas) {
    this.c = canvas; this.t = []; this.a = []; this.tmax = 10;
  }
  Swing.prototype.reset = function (tmax) { this.t = []; this.a = []; if (tmax) { this.tmax = tmax; } this.draw(); };
  Swing.prototype.add = function (t, a) {
    for (var i = 0; i < t.length; i++) { this.t.push(t[i]); this.a.push(a[i]); }
    this.draw();
  };
  Swing.prototype.draw = function () {
    var c = this.c, g = c.getContext("2d"), w = c.width, h = c.height, n = this.t.length;
    g.clearRect(0, 0, w, h);
    g.strokeStyle = "#ccc"; g.beginPath(); g.moveTo(0, h / 2); g.lineTo(w, h / 2); g.stroke();
    if (!n) { return; }
    var amax = 1e-6, tmax = Math.max(this.tmax, this.t[n - 1]);
    for (var i = 0; i < n; i++) { amax = Math.max(amax, Math.abs(this.a[i])); }
    g.strokeStyle = "#b22"; g.lineWidth = 1; g.beginPath();
    for (var j = 0; j < n; j++) {
      var x = this.t[j] / tmax * (w - 4) + 2, y = h / 2 - this.a[j] / amax * (h / 2 - 6);
      if (j) { g.lineTo(x, y); } else { g.moveTo(x, y); }
    }
    g.stroke();
    g.fillStyle = "#333"; g.font = "12px sans-serif";
    g.fillText("±" + amax.toFixed(3) + " rad, " + this.t[n - 1].toFixed(1) + " s", 6, 14);
  };

  function home() {
    var swing = new Swing($("swing")), mid = null;
    document.querySelectorAll("button[data-action]").forEach(function (b) {
      b.addEventListener("click", function () { act(b.getAttribute("data-action")); });
    });
    function show(s) {
      var el = $("state");
      el.textContent = s.state; el.className = "state state-" + s.state;
      $("words").textContent = s.words || "";
      var f = $("fault");
      if (s.state === "FAULT" && s.fault) { f.textContent = s.fault; f.hidden = false; } else { f.hidden = true; }
      if (s.recipe !== undefined) { $("recipe").textContent = s.recipe ? s.recipe.number + " " + s.recipe.name : "–"; }
      if (s.part_id !== undefined) { $("part-id").textContent = s.part_id || "–"; }
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
      if (s.state === "IDLE" && s.previous === "PUBLISHING" && s.measurement_id) {
        var p = $("latest");
        p.textContent = "latest result: ";
        var a = document.createElement("a");
        a.id = "latest-link"; a.href = "/results/" + s.measurement_id;
        a.textContent = "J = " + (s.J !== null && s.J !== undefined ? s.J.toPrecision(7) + " kg·m²" : "n/a");
        p.appendChild(a);
      }
    }
    var pf = $("part-form");
    if (pf) {
      pf.addEventListener("submit", function (e) {
        e.preventDefault();
        var fd = new FormData(pf);
        if (!fd.get("part_id")) { fd.delete("part_id"); }
        act(pf.getAttribute("data-action"), new URLSearchParams(fd));
      });
    }
    var es = new EventSource("/events");
    es.addEventListener("state", function (e) { var s = JSON.parse(e.data); logState(s); show(s); });
    es.addEventListener("tick", function (e) {
      var s = JSON.parse(e.data);
      document.body.setAttribute("data-live", "1");  // connected: every transition from now on is shown
      show(s);
      if (s.samples) {
        if (s.reset || s.measurement_id !== mid) { mid = s.measurement_id; swing.reset(s.capture_duration + (s.pre_trigger || 0)); }
        swing.add(s.samples.t, s.samples.angle);
      }
    });
    es.onerror = function () { $("words").textContent = "connection to the appliance lost; retrying"; };
  }

  function setup() {
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
  return {home: home, setup: setup, act: act};
})();
