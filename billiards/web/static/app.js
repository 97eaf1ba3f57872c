// sagu viewer: the page of `python -m billiards.web` (docs/viewer.md). Plain JavaScript, no build step,
// nothing loaded from elsewhere. Three views share one table canvas and one shot panel:
//   replay  -- a recorded run's shots (GET /api/runs, /api/run), each played again exactly by POST /api/shot, and for a
//              search what it considered (POST /api/considered, asked per shot when the shot is shown);
//   lab     -- drag balls, aim, shoot (POST /api/shot), ask an agent (POST /api/agent);
//   play    -- a match against a league player (POST /api/match, /api/match/{id}/shot).
// What the page shows is also exposed on window.billiards (and the canvas's data-final attribute) for tests.
"use strict";
(function () {
  const $ = (id) => document.getElementById(id);
  const BALL_COLORS = ["#f7f7f2", "#f2c400", "#d7261e", "#9c0d2b"];
  const BALL_EDGES = ["#222", "#222", "#fff", "#fff"];
  const CLOTH = "#1f6e43", RAIL = "#5a3a1e", DIAMOND = "#e8e0c8", RAIL_W = 0.12;

  // what tests and people can read: the view, the last shot's end, the replay's and the match's progress
  const B = window.billiards = {
    ready: false, view: "replay", errors: [], busy: 0,
    anim: { state: "idle", t: 0, duration: 0, fps: null, frames: 0, wall: 0 },
    last: null,
    replay: { path: null, unit: null, index: -1, count: 0, finals: {}, frames: {}, done: false, considered: {}, check: null },
    lab: { shots: 0, final: null, agent: null },
    match: { state: null, shots: 0, finals: [], over: false, pending: false },
  };

  const S = {
    config: null, physics: "korean_medium", table: null,
    balls: null, before: null,
    aim: { theta: Math.PI / 2, p: 0.5, a: 0, b: 0 }, played: null, shooter: 0,
    anim: null, playing: false, speed: 1,
    preview: null, previewToken: 0, previewTimer: null, cloud: null,
    shown: null, drag: null,
    run: null, unit: null, index: -1, replayToken: 0, shotCache: new Map(), considered: null, consideredCache: new Map(),
    match: null,
  };

  // ------------------------------------------------------------------ the server

  async function api(method, url, body) {
    const opts = { method, headers: {} };
    if (body !== undefined) {
      opts.headers["content-type"] = "application/json";
      opts.body = JSON.stringify(body);
    }
    B.busy++;
    try {
      const r = await fetch(url, opts);
      let data = null;
      try { data = await r.json(); } catch (e) { data = null; }
      if (!r.ok) throw new Error((data && data.error) || (r.status + " " + r.statusText));
      return data;
    } finally {
      B.busy--;
    }
  }

  function status(text, isError) {
    const el = $("status");
    el.textContent = text;
    el.title = text;
    el.classList.toggle("error", !!isError);
    if (isError) B.errors.push(text);
  }

  // run an async handler; its error goes to the status line (never an unhandled rejection)
  function guard(fn) {
    return function (...args) {
      Promise.resolve().then(() => fn.apply(this, args)).catch((err) => status(String(err.message || err), true));
    };
  }

  // ------------------------------------------------------------------ geometry and drawing

  function geom() {
    const c = $("table"), t = S.table, W = t.table_width, L = t.table_length, m = RAIL_W + 0.05;
    const s = Math.min(c.width / (W + 2 * m), c.height / (L + 2 * m));
    const ox = (c.width - W * s) / 2, oy = (c.height - L * s) / 2;
    return {
      s, W, L, R: t.ball_radius,
      X: (x) => ox + x * s, Y: (y) => oy + (L - y) * s,
      inv: (px, py) => [(px - ox) / s, L - (py - oy) / s],
    };
  }

  function drawTable(ctx, g) {
    const r = RAIL_W * g.s;
    ctx.fillStyle = RAIL;
    ctx.fillRect(g.X(0) - r, g.Y(g.L) - r, g.W * g.s + 2 * r, g.L * g.s + 2 * r);
    ctx.fillStyle = CLOTH;
    ctx.fillRect(g.X(0), g.Y(g.L), g.W * g.s, g.L * g.s);
    ctx.fillStyle = DIAMOND;
    const dot = (x, y, rad) => { ctx.beginPath(); ctx.arc(x, y, rad, 0, 2 * Math.PI); ctx.fill(); };
    const half = RAIL_W / 2;
    for (let k = 1; k < 8; k++) {  // long rails: every l/8 (the quarters larger), short rails: every w/4
      const big = k % 2 === 0;
      for (const x of [-half, g.W + half]) dot(g.X(x), g.Y(g.L * k / 8), big ? 3 : 1.8);
    }
    for (let k = 1; k < 4; k++) for (const y of [-half, g.L + half]) dot(g.X(g.W * k / 4), g.Y(y), 3);
  }

  function drawBall(ctx, g, k, xy, alpha) {
    ctx.globalAlpha = alpha === undefined ? 1 : alpha;
    ctx.beginPath();
    ctx.arc(g.X(xy[0]), g.Y(xy[1]), g.R * g.s, 0, 2 * Math.PI);
    ctx.fillStyle = BALL_COLORS[k];
    ctx.fill();
    ctx.lineWidth = 1;
    ctx.strokeStyle = "#000";
    ctx.stroke();
    ctx.globalAlpha = 1;
  }

  function drawPath(ctx, g, xy, k, upto, width, alpha) {
    if (upto < 1) return;
    ctx.globalAlpha = alpha;
    for (const [color, w] of [[BALL_EDGES[k], width + 1.6], [BALL_COLORS[k], width]]) {
      ctx.beginPath();
      ctx.moveTo(g.X(xy[0][k][0]), g.Y(xy[0][k][1]));
      for (let i = 1; i <= upto; i++) ctx.lineTo(g.X(xy[i][k][0]), g.Y(xy[i][k][1]));
      ctx.strokeStyle = color;
      ctx.lineWidth = w;
      ctx.lineJoin = "round";
      ctx.stroke();
    }
    ctx.globalAlpha = 1;
  }

  function drawAim(ctx, g, from, theta, p, color, dashed) {
    const len = 0.12 + 0.55 * p;
    ctx.beginPath();
    ctx.moveTo(g.X(from[0]), g.Y(from[1]));
    ctx.lineTo(g.X(from[0] + len * Math.cos(theta)), g.Y(from[1] + len * Math.sin(theta)));
    ctx.strokeStyle = color;
    ctx.lineWidth = 2;
    ctx.setLineDash(dashed ? [6, 4] : []);
    ctx.stroke();
    ctx.setLineDash([]);
  }

  function drawEvents(ctx, g, shot, t) {
    let n = 0;
    for (const e of shot.events) {
      if (e.t > t || e.ball !== shot.shooter) continue;
      if (e.kind === "ball_ball") {
        n++;
        ctx.beginPath();
        ctx.arc(g.X(e.xy[0]), g.Y(e.xy[1]), 1.6 * g.R * g.s, 0, 2 * Math.PI);
        ctx.strokeStyle = BALL_COLORS[e.other];
        ctx.lineWidth = 2;
        ctx.stroke();
        ctx.fillStyle = "#fff";
        ctx.font = "bold 11px system-ui, sans-serif";
        ctx.fillText(String(n), g.X(e.xy[0]) + 1.8 * g.R * g.s, g.Y(e.xy[1]) - 1.8 * g.R * g.s);
      } else {
        const x = g.X(e.xy[0]), y = g.Y(e.xy[1]);
        ctx.beginPath();
        ctx.moveTo(x, y - 5); ctx.lineTo(x + 4.5, y + 3.5); ctx.lineTo(x - 4.5, y + 3.5); ctx.closePath();
        ctx.fillStyle = "#ffdd88";
        ctx.fill();
      }
    }
  }

  function frameIndex(times, t) {  // the last sample at or before t
    let lo = 0, hi = times.length - 1;
    if (t >= times[hi]) return hi;
    while (lo < hi) {
      const mid = (lo + hi + 1) >> 1;
      if (times[mid] <= t) lo = mid; else hi = mid - 1;
    }
    return lo;
  }

  function positionsAt(paths, t) {
    const i = frameIndex(paths.t, t), xy = paths.xy;
    if (i >= paths.t.length - 1) return xy[xy.length - 1];
    const t0 = paths.t[i], t1 = paths.t[i + 1], f = t1 > t0 ? (t - t0) / (t1 - t0) : 0;
    return xy[i].map((p, k) => [p[0] + f * (xy[i + 1][k][0] - p[0]), p[1] + f * (xy[i + 1][k][1] - p[1])]);
  }

  function draw() {
    if (!S.table || !S.balls) return;
    const c = $("table"), ctx = c.getContext("2d"), g = geom();
    ctx.clearRect(0, 0, c.width, c.height);
    drawTable(ctx, g);
    const a = S.anim;
    if (!a && S.preview && B.view === "lab") {  // the exact path of the shot as set, faint
      const p = S.preview.paths;
      for (const k of [1, 2, 3, 0]) drawPath(ctx, g, p.xy, k, p.xy.length - 1, 1.2, 0.45);
      S.preview.final.forEach((xy, k) => drawBall(ctx, g, k, xy, 0.35));
    }
    if (S.cloud && B.view !== "replay") {
      for (let i = 0; i < S.cloud.white_ends.length; i++) {
        const e = S.cloud.white_ends[i];
        ctx.beginPath();
        ctx.arc(g.X(e[0]), g.Y(e[1]), 2.5, 0, 2 * Math.PI);
        ctx.fillStyle = S.cloud.scored[i] ? "#9cff9c" : "#ff9c9c";
        ctx.fill();
      }
    }
    if (B.view === "replay") drawConsidered(ctx, g);
    let balls = S.balls;
    if (a) {
      const p = a.shot.paths, upto = frameIndex(p.t, a.t);
      for (const k of [1, 2, 3, 0]) drawPath(ctx, g, p.xy, k, upto, 1.6, 0.95);
      drawEvents(ctx, g, a.shot, a.t);
      balls = a.t >= a.duration ? a.shot.final : positionsAt(p, a.t);
      if (a.t === 0) drawShotAim(ctx, g, a.shot);
    } else if (B.view !== "replay" && S.balls) {
      drawAim(ctx, g, S.balls[S.shooter], S.aim.theta, S.aim.p, "#ffffff", true);
    }
    balls.forEach((xy, k) => drawBall(ctx, g, k, xy));
    if (S.drag && S.drag.kind === "ball" && overlaps(S.balls, S.drag.k)) {
      const xy = S.balls[S.drag.k];
      ctx.beginPath();
      ctx.arc(g.X(xy[0]), g.Y(xy[1]), g.R * g.s + 3, 0, 2 * Math.PI);
      ctx.strokeStyle = "#ff3b30";
      ctx.lineWidth = 2;
      ctx.stroke();
    }
  }

  // the search's candidates (thin aim lines: green scores exactly, red fouls, grey misses) and the
  // cloud of the recorded shot's noisy replays (cue-ball ends, green: scored) for the shot shown
  function drawConsidered(ctx, g) {
    const c = S.considered;
    if (!c || !S.unit || c.index !== S.index || !$("rp-considered").checked) return;
    const r = c.data, from = S.unit.shots[S.index].positions[S.unit.shots[S.index].shooter];
    const top = r.considered && r.considered.candidates ? r.considered.candidates.top : [];
    for (const cand of top.slice().reverse()) {
      const [theta, p] = cand.action, len = 0.12 + 0.55 * p;
      ctx.beginPath();
      ctx.moveTo(g.X(from[0]), g.Y(from[1]));
      ctx.lineTo(g.X(from[0] + len * Math.cos(theta)), g.Y(from[1] + len * Math.sin(theta)));
      ctx.strokeStyle = cand.score ? "rgba(120,255,140,0.8)" : cand.foul ? "rgba(255,110,110,0.7)" : "rgba(220,220,220,0.45)";
      ctx.lineWidth = 1.2;
      ctx.stroke();
    }
    if (r.noisy) {
      for (let i = 0; i < r.noisy.white_ends.length; i++) {
        const e = r.noisy.white_ends[i];
        ctx.beginPath();
        ctx.arc(g.X(e[0]), g.Y(e[1]), 2.5, 0, 2 * Math.PI);
        ctx.fillStyle = r.noisy.scored[i] ? "#9cff9c" : "#ff9c9c";
        ctx.fill();
      }
    }
  }

  function drawShotAim(ctx, g, shot) {
    const from = shot.positions[shot.shooter];
    drawAim(ctx, g, from, shot.commanded[0], shot.commanded[1], "#ffffff", true);
    if (shot.played && shot.played.some((v, i) => v !== shot.commanded[i])) drawAim(ctx, g, from, shot.played[0], shot.played[1], "#ff9f1c", false);
  }

  function overlaps(balls, k) {
    const R = S.table.ball_radius;
    return balls.some((b, j) => j !== k && Math.hypot(b[0] - balls[k][0], b[1] - balls[k][1]) < 2 * R);
  }

  // ------------------------------------------------------------------ the cue-ball diagram and the shot panel

  function drawTip() {
    const c = $("tip"), ctx = c.getContext("2d"), cx = c.width / 2, cy = c.height / 2, r = 46;
    const maxE = S.table ? S.table.max_english : 1;
    ctx.clearRect(0, 0, c.width, c.height);
    ctx.beginPath(); ctx.arc(cx, cy, r, 0, 2 * Math.PI);
    ctx.fillStyle = BALL_COLORS[S.shooter]; ctx.fill(); ctx.strokeStyle = "#000"; ctx.lineWidth = 1; ctx.stroke();
    ctx.beginPath(); ctx.arc(cx, cy, r * maxE, 0, 2 * Math.PI);
    ctx.setLineDash([3, 3]); ctx.strokeStyle = "#777"; ctx.stroke(); ctx.setLineDash([]);
    ctx.beginPath(); ctx.moveTo(cx - r, cy); ctx.lineTo(cx + r, cy); ctx.moveTo(cx, cy - r); ctx.lineTo(cx, cy + r);
    ctx.strokeStyle = "rgba(0,0,0,0.15)"; ctx.stroke();
    // seen from behind the cue: a > 0 (left english) is left of centre, b > 0 above
    const spot = (a, b, fill, ring) => {
      const n = Math.max(1, Math.hypot(a, b));
      ctx.beginPath(); ctx.arc(cx - (a / n) * r * maxE, cy - (b / n) * r * maxE, 5, 0, 2 * Math.PI);
      if (fill) { ctx.fillStyle = fill; ctx.fill(); }
      ctx.strokeStyle = ring; ctx.lineWidth = 2; ctx.stroke();
    };
    spot(S.aim.a, S.aim.b, "#1f3b2c", "#fff");
    if (S.played) spot(S.played[2], S.played[3], null, "#ff9f1c");
  }

  const fmt = (x, d) => Number(x).toFixed(d);
  const deg = (theta) => ((theta * 180 / Math.PI) % 360 + 360) % 360;

  function showAim() {
    $("in-theta").value = fmt(deg(S.aim.theta), 2);
    $("in-power").value = S.aim.p;
    $("power-val").textContent = fmt(S.aim.p, 2);
    $("in-a").value = fmt(S.aim.a, 2);
    $("in-b").value = fmt(S.aim.b, 2);
    drawTip();
  }

  function describeShot(shot) {
    const r = shot.result, out = $("outcome");
    const hits = Object.entries(r.hits).map(([k, v]) => k + (v ? " \u2713" : " \u2717")).join(", ");
    out.className = "outcome " + r.label;
    out.textContent = r.label.toUpperCase() + (shot.who ? " (" + shot.who + ")" : "") + ": first contact " + (r.first_contact || "none")
      + "; " + hits + "; " + r.cushions + " cushion" + (r.cushions === 1 ? "" : "s") + "; " + fmt(r.duration, 2) + " s";
    const c = shot.commanded, p = shot.played;
    let text = "commanded: \u03b8 " + fmt(deg(c[0]), 2) + "\u00b0, p " + fmt(c[1], 3) + ", a " + fmt(c[2], 2) + ", b " + fmt(c[3], 2);
    if (p && p.some((v, i) => v !== c[i])) {
      text += " | played (noise" + (shot.level !== null && shot.level !== undefined ? ", level " + fmt(shot.level, 2) : "") + "): \u03b8 "
        + fmt(deg(p[0]), 2) + "\u00b0, p " + fmt(p[1], 3) + ", a " + fmt(p[2], 2) + ", b " + fmt(p[3], 2);
    }
    if (shot.caption) text = shot.caption + ". " + text;
    $("action-text").textContent = text;
  }

  // ------------------------------------------------------------------ animation

  // play `shot` (an /api/shot answer) from t = 0; resolves true at its end, false if another shot replaced it
  function animate(shot) {
    if (S.anim && S.anim.resolve) S.anim.resolve(false);
    return new Promise((resolve) => {
      S.anim = { shot, t: 0, duration: shot.result.duration, last: null, resolve, frames: 0, wall: 0, state: "running" };
      S.shown = shot;
      S.aim = { theta: shot.commanded[0], p: shot.commanded[1], a: shot.commanded[2], b: shot.commanded[3] };
      S.played = shot.played && shot.played.some((v, i) => v !== shot.commanded[i]) ? shot.played : null;
      S.shooter = shot.shooter;
      showAim();
      describeShot(shot);
      B.anim.state = "running";
      B.anim.duration = shot.result.duration;
      requestAnimationFrame(tick);
    });
  }

  function tick(now) {
    const a = S.anim;
    if (!a || a.state !== "running") return;
    if (S.playing && a.last !== null) {
      const dt = (now - a.last) / 1000;
      a.t = Math.min(a.duration, a.t + dt * S.speed);
      a.frames++;
      a.wall += dt;
      B.anim.frames = a.frames;
      B.anim.wall = a.wall;
    }
    a.last = now;
    updateClock();
    if (a.t >= a.duration) { finish(); return; }
    draw();
    requestAnimationFrame(tick);
  }

  function finish() {
    const a = S.anim;
    a.t = a.duration;
    a.state = "done";
    S.balls = a.shot.final.map((p) => p.slice());
    B.last = { final: a.shot.final, result: a.shot.result, played: a.shot.played };
    B.anim.state = "done";
    if (a.wall > 0.2) B.anim.fps = a.frames / a.wall;
    B.anim.frames = a.frames;
    $("table").dataset.final = JSON.stringify(a.shot.final);
    updateClock();
    draw();
    if (a.resolve) { const r = a.resolve; a.resolve = null; r(true); }
  }

  function updateClock() {
    const a = S.anim;
    const t = a ? a.t : 0, d = a ? a.duration : 0;
    $("clock").textContent = fmt(t, 2) + " s";
    $("scrub").value = d > 0 ? Math.round(1000 * t / d) : 0;
    B.anim.t = t;
    $("btn-play").innerHTML = S.playing ? "&#10074;&#10074;" : "&#9654;";
  }

  function setPlaying(on) {
    S.playing = on;
    updateClock();
  }

  // ------------------------------------------------------------------ views

  function setView(view) {
    B.view = view;
    for (const b of document.querySelectorAll("#tabs button")) b.classList.toggle("active", b.dataset.view === view);
    for (const v of ["replay", "lab", "play"]) $("panel-" + v).classList.toggle("hidden", v !== view);
    $("btn-shoot").classList.toggle("hidden", view === "replay");
    cancelAnim();
    S.preview = null;
    S.cloud = null;
    S.played = null;
    if (view === "lab") {
      setTable($("lab-physics").value);
      if (!S.labBalls) S.labBalls = S.table.opening_rack.map((p) => p.slice());
      S.balls = S.labBalls;
      S.shooter = 0;
      requestPreview();
    } else if (view === "play") {
      setTable(S.match ? S.match.physics : "korean_medium");
      S.balls = S.match ? S.match.positions.map((p) => p.slice()) : S.table.opening_rack.map((p) => p.slice());
      S.shooter = 0;
    } else {
      setTable(S.run ? S.run.physics : S.physics);
      if (S.unit && S.index >= 0) S.balls = S.unit.shots[S.index].positions;
      else if (!S.balls) S.balls = S.table.opening_rack.map((p) => p.slice());
    }
    showAim();
    draw();
  }

  function cancelAnim() {
    S.replayToken++;
    if (S.anim && S.anim.resolve) { const r = S.anim.resolve; S.anim.resolve = null; r(false); }
    S.anim = null;
    setPlaying(false);
    B.anim.state = "idle";
  }

  function setTable(name) {
    S.physics = name;
    S.table = S.config.physics[name] || S.config.physics.korean_medium;
  }

  // ------------------------------------------------------------------ replay

  async function loadRuns() {
    const data = await api("GET", "/api/runs");
    const sel = $("run-select");
    const groups = { p3: "search runs: P3 chains", p1: "search runs: P1 innings (played again on demand)",
      scorecard: "benchmark scorecards (played again on demand)", training: "training runs: evaluation innings (played again on demand)",
      league: "leagues (played again on demand)", web: "matches played here" };
    for (const kind of Object.keys(groups)) {
      const runs = data.runs.filter((r) => r.kind === kind);
      if (!runs.length) continue;
      const og = document.createElement("optgroup");
      og.label = groups[kind];
      for (const r of runs) {
        const o = document.createElement("option");
        o.value = r.path;
        o.textContent = r.path + (r.noise && r.noise !== "none" ? " [" + r.noise + "]" : "") + (r.replayable ? "" : " (cannot be played again)");
        if (r.why_not) o.title = r.why_not;
        og.appendChild(o);
      }
      sel.appendChild(og);
    }
    return data.runs.length;
  }

  async function openRun(path) {
    cancelAnim();
    S.run = null; S.unit = null; S.index = -1; S.shotCache.clear(); S.considered = null; S.consideredCache.clear();
    showConsidered(null);
    Object.assign(B.replay, { path, unit: null, index: -1, count: 0, finals: {}, frames: {}, done: false, considered: {}, check: null });
    const us = $("unit-select");
    us.innerHTML = "";
    us.disabled = true;
    if (!path) return;
    status("loading " + path + " ...");
    const run = await api("GET", "/api/run?path=" + encodeURIComponent(path));
    S.run = run;
    let note = run.note || (run.kind + " run, " + run.physics + ", noise " + run.noise);
    if (run.summary) {  // a scorecard: its figures
      const figures = Object.entries(run.summary).filter(([, v]) => v && typeof v === "object" && "mean" in v)
        .map(([k, v]) => k + " " + fmt(v.mean, 4) + (v.ci95 ? " [" + fmt(v.ci95[0], 4) + ", " + fmt(v.ci95[1], 4) + "]" : ""));
      note += ". " + run.summary.track + ", " + (run.agent && run.agent.name ? run.agent.name : "") + ": " + figures.join("; ");
    }
    $("run-note").textContent = note;
    if (run.physics) setTable(run.physics);
    for (const u of run.units) {
      const o = document.createElement("option");
      o.value = String(u.id);
      o.textContent = u.title;
      us.appendChild(o);
    }
    const playable = run.units.length && run.replayable !== false;
    us.disabled = !playable;
    status(playable ? path + ": " + run.units.length + " to replay" : path + ": nothing to replay", false);
    if (playable) await openUnit(run.units[0].id);
  }

  async function openUnit(id) {
    cancelAnim();
    const run = S.run;
    let unit = run.units.find((u) => String(u.id) === String(id));
    if (!unit) return;
    if (!unit.shots) {  // played again by the server: a league's match, a scorecard's unit, a P1 run, a training evaluation
      const what = { league: "match " + id + " (the league's players, its seed)", scorecard: "unit " + id + " (the scorecard's agent, its seed)",
        p1: "the whole P1 run (its innings step together)", training: "the evaluation (the run's shipped policy)" }[run.kind] || String(id);
      status("playing " + what + " again ...");
      const one = await api("GET", "/api/run?path=" + encodeURIComponent(run.path) + "&unit=" + encodeURIComponent(id));
      unit = Object.assign(unit, one.units[0]);
      const check = unit.check || (unit.reproduced === false ? "the replay does not give the recorded scores" : "the recorded scores reproduced");
      status(unit.title + ": " + unit.shots.length + " shots; " + check, false);
      $("run-note").textContent = (run.note ? run.note + ". " : "") + check[0].toUpperCase() + check.slice(1) + ".";
      B.replay.check = { reproduced: unit.reproduced, check };
    }
    S.unit = unit; S.index = -1; S.shotCache.clear(); S.considered = null; S.consideredCache.clear();
    showConsidered(null);
    Object.assign(B.replay, { unit: id, index: -1, count: unit.shots.length, finals: {}, frames: {}, done: false, considered: {} });
    await showShot(0, false);
  }

  // what the run's search considers for shot k (asked once per shot, when the shot is shown)
  function consideredRequest(k) {
    const shot = S.unit.shots[k];
    if (!S.consideredCache.has(k)) {
      const body = { run: S.run.path, positions: shot.positions, commanded: shot.commanded, shooter: shot.shooter,
        seed: S.unit.seed !== undefined && S.unit.seed !== null ? S.unit.seed : 0, replays: 50 };
      if (shot.level !== null && shot.level !== undefined) body.level = shot.level;
      S.consideredCache.set(k, api("POST", "/api/considered", body));
    }
    return S.consideredCache.get(k);
  }

  async function loadConsidered(k, token) {
    const shot = S.unit && S.unit.shots[k];
    if (!S.run || !S.run.considers || !shot || shot.agent_shot === false || !$("rp-considered").checked) {
      if (token === S.replayToken) showConsidered(null, shot && shot.agent_shot === false ? "an opponent's shot: not the scored agent's" : "");
      return;
    }
    $("considered-info").textContent = "asking the search what it considers here ...";
    let r;
    try { r = await consideredRequest(k); } catch (err) {
      S.consideredCache.delete(k);
      if (S.index === k) showConsidered(null, "the search cannot be asked: " + (err.message || err));
      return;
    }
    B.replay.considered[k] = r;
    if (S.index !== k) return;
    S.considered = { index: k, data: r };
    showConsidered(r);
    draw();
  }

  function showConsidered(r, text) {
    const info = $("considered-info"), table = $("candidates"), body = table.querySelector("tbody");
    body.innerHTML = "";
    if (!r) { info.textContent = text || ""; table.classList.add("hidden"); return; }
    const c = r.considered;
    let t = r.agent + ", asked again on this table (seed " + r.seed + ", " + r.sims + " simulations, " + fmt(1000 * r.seconds, 1) + " ms)";
    if (c) {
      if (c.candidates) t += ": its first " + c.candidates.count + " candidates, " + c.candidates.scoring + " score and " + c.candidates.fouling + " foul exactly (lines: green scores, red fouls)";
      if (c.r1 !== undefined) t += "; its estimate of its pick: r1 = " + fmt(c.r1, 3) + (c.value !== undefined ? ", value " + fmt(c.value, 3) : "");
    }
    if (r.same_choice === true) t += "; it picks the recorded shot again.";
    else if (r.same_choice === false) t += "; it picks another shot now (in the run its generator had another state).";
    const n = r.noisy;
    if (n) {
      t += " The recorded shot under " + r.noise + " noise: " + Math.round(100 * n.score_share) + " % of " + n.n + " noisy replays score, "
        + Math.round(100 * n.foul_share) + " % foul (dots: where the cue ball ends; green: scored)";
      if (n.leave) {
        t += "; the value of the leave where it scores: " + (n.leave.mean_if_scored === null ? "none scores" : fmt(n.leave.mean_if_scored, 3))
          + " (position weight " + n.leave.position + ", the search's estimate of the shot " + fmt(n.leave.estimate, 3) + ")";
      }
      t += ".";
    }
    info.textContent = t;
    const top = c && c.candidates ? c.candidates.top : [];
    const rec = r.recorded;
    top.forEach((cand, i) => {
      const tr = document.createElement("tr");
      if (rec && cand.action.every((v, j) => v === rec[j])) tr.className = "chosen";
      const a = cand.action, label = cand.score ? "score" : cand.foul ? "foul" : "miss";
      for (const [v, cls] of [[String(i + 1), ""], [fmt(deg(a[0]), 1), ""], [fmt(a[1], 2), ""], [fmt(a[2], 2), ""], [fmt(a[3], 2), ""], [label, label]]) {
        const td = document.createElement("td");
        td.textContent = v;
        if (cls) td.className = cls;
        tr.appendChild(td);
      }
      body.appendChild(tr);
    });
    table.classList.toggle("hidden", !top.length);
  }

  function shotRequest(k) {
    const shot = S.unit.shots[k];
    if (!S.shotCache.has(k)) {
      S.shotCache.set(k, api("POST", "/api/shot", { positions: shot.positions, action: shot.played, physics: S.run.physics,
        noise: "none", shooter: shot.shooter }).then((r) => Object.assign(r, {
        commanded: shot.commanded, played: shot.played, level: shot.level, caption: shot.caption, who: shot.who })));
    }
    return S.shotCache.get(k);
  }

  // show shot k (its table, its action) and animate it; with `play`, go on through the following shots
  async function showShot(k, play) {
    if (!S.unit || k < 0 || k >= S.unit.shots.length) return;
    const token = ++S.replayToken;
    if (S.anim && S.anim.resolve) { const r = S.anim.resolve; S.anim.resolve = null; r(false); }
    S.index = k;
    B.replay.index = k;
    S.balls = S.unit.shots[k].positions;
    $("shot-label").textContent = "shot " + (k + 1) + " / " + S.unit.shots.length;
    if (!S.considered || S.considered.index !== k) { S.considered = null; showConsidered(null); }
    loadConsidered(k, token);
    const shot = await shotRequest(k);
    if (token !== S.replayToken) return;
    if (k + 1 < S.unit.shots.length) shotRequest(k + 1).catch(() => {});
    if (play) setPlaying(true);
    const ended = await animate(shot);
    if (!ended || token !== S.replayToken) return;
    B.replay.finals[k] = shot.final;
    B.replay.frames[k] = S.anim ? S.anim.frames : 0;  // animation frames this shot was drawn in
    if (k === S.unit.shots.length - 1) {
      B.replay.done = true;
      setPlaying(false);
      status("end of " + (S.unit.title || "the replay"));
      return;
    }
    if (S.playing) {
      await new Promise((r) => setTimeout(r, 250 / S.speed));
      if (token === S.replayToken && S.playing) await showShot(k + 1, true);
    }
  }

  // ------------------------------------------------------------------ lab

  function currentAction() {
    return [S.aim.theta, S.aim.p, S.aim.a, S.aim.b];
  }

  function requestPreview() {
    if (B.view !== "lab" || !$("lab-preview").checked) { S.preview = null; return; }
    clearTimeout(S.previewTimer);
    S.previewTimer = setTimeout(guard(async () => {
      const token = ++S.previewToken;
      if (overlapsAny(S.balls)) { S.preview = null; draw(); return; }
      const r = await api("POST", "/api/shot", { positions: S.balls, action: currentAction(), physics: S.physics, noise: "none" });
      if (token !== S.previewToken || S.anim) return;
      S.preview = r;
      draw();
    }), 90);
  }

  function overlapsAny(balls) {
    return balls.some((_, k) => overlaps(balls, k));
  }

  async function labShoot(keepCloud) {
    cancelAnim();
    S.previewToken++;
    S.preview = null;
    if (!keepCloud) S.cloud = null;
    const before = S.balls.map((p) => p.slice());
    if (overlapsAny(before)) { status("two balls overlap: move one before shooting", true); draw(); return; }
    const r = await api("POST", "/api/shot", { positions: before, action: currentAction(), physics: S.physics,
      noise: $("lab-noise").value, seed: Number($("lab-seed").value) || 0 });
    S.before = before;
    $("btn-undo").disabled = false;
    setPlaying(true);
    status("shot: " + r.result.label);
    const ended = await animate(r);
    if (!ended) return;
    S.labBalls = S.balls;
    Object.assign(B.lab, { shots: B.lab.shots + 1, final: r.final, positions: before, action: r.commanded, played: r.played });
    setPlaying(false);
  }

  async function askAgent(forMatch) {
    const spec = forMatch ? $("hint-select").value : $("agent-select").value;
    const noise = forMatch ? S.match.noise : $("lab-noise").value;
    status("asking " + spec + " ...");
    const r = await api("POST", "/api/agent", { positions: S.balls, agent: spec, physics: S.physics, noise,
      seed: Number($("lab-seed").value) || 0, replays: 50 });
    S.aim = { theta: r.action[0], p: r.action[1], a: r.action[2], b: r.action[3] };
    S.played = null;
    showAim();
    B.lab.agent = r;
    let text = spec + " answered in " + fmt(1000 * r.seconds, 1) + " ms";
    if (r.sims) text += " (" + r.sims + " simulations)";
    const c = r.considered;
    if (c) {
      if (c.r1 !== undefined) text += "; its estimate of the chosen shot: r1 = " + fmt(c.r1, 3);
      if (c.value !== undefined) text += ", value " + fmt(c.value, 3);
      if (c.candidates) text += "; its first " + c.candidates.count + " candidates: " + c.candidates.scoring + " score, " + c.candidates.fouling + " foul exactly";
    }
    if (r.noisy) text += "; under " + noise + " noise " + Math.round(100 * r.noisy.score_share) + " % of " + r.noisy.n + " noisy replays score (dots: where the cue ball ends)";
    if (r.noisy && r.noisy.leave && r.noisy.leave.mean_if_scored !== null) {
      text += "; the value of the leave where it scores: " + fmt(r.noisy.leave.mean_if_scored, 3) + " (position weight " + r.noisy.leave.position + ")";
    }
    (forMatch ? $("match-info") : $("agent-info")).textContent = text;
    S.cloud = r.noisy;
    status(spec + " answered");
    if (!forMatch) await labShoot(true);
    else draw();
  }

  // ------------------------------------------------------------------ play

  function showMatch(state) {
    S.match = state;
    B.match.state = state;
    B.match.over = state.over;
    $("score-opp-name").textContent = state.opponent + " (yellow)";
    $("score-human").textContent = state.scores.human;
    $("score-opp").textContent = state.scores[state.opponent];
    let text = "to " + state.target + " points, noise " + state.noise + "; innings " + state.innings + ", shots " + state.shots;
    if (state.over) {
      text = (state.winner === "human" ? "You win" : state.winner ? state.opponent + " wins" : "A draw") + " (" + state.scores.human + " : "
        + state.scores[state.opponent] + ")." + (state.saved ? " Saved: " + state.saved : "");
    } else if (state.to_play === "human") text += "; your shot";
    $("match-info").textContent = text;
    $("btn-hint").disabled = state.over || state.to_play !== "human";
    $("btn-shoot").disabled = state.over;
  }

  async function playShots(shots) {
    setPlaying(true);
    for (const s of shots) {
      S.balls = s.positions;
      const ended = await animate(s);
      if (!ended) return false;
      B.match.shots++;
      B.match.finals.push(s.final);
      $("score-human").textContent = s.scores[0];
      $("score-opp").textContent = s.scores[1];
      await new Promise((r) => setTimeout(r, 200 / S.speed));
    }
    setPlaying(false);
    return true;
  }

  async function startMatch() {
    B.match.pending = true;
    try { await startMatchNow(); } finally { B.match.pending = false; }
  }

  async function startMatchNow() {
    cancelAnim();
    S.cloud = null;
    const body = { opponent: $("play-opponent").value, noise: $("play-noise").value, target: Number($("play-target").value) || 1,
      first: $("play-first").value, seed: Number($("play-seed").value) || 0 };
    status("starting a match against " + body.opponent + " ...");
    const r = await api("POST", "/api/match", body);
    Object.assign(B.match, { shots: 0, finals: [], over: false });
    setTable(r.state.physics);
    S.balls = r.shots.length ? r.shots[0].positions : r.state.positions;
    showMatch(Object.assign({}, r.state, { over: false }));
    draw();
    await playShots(r.shots);
    showMatch(r.state);
    S.balls = r.state.positions.map((p) => p.slice());
    S.shooter = 0;
    showAim();
    draw();
    status("match started: " + (r.state.over ? "over" : "your shot"));
  }

  async function matchShoot() {
    if (!S.match || S.match.over) { status("start a match first", true); return; }
    B.match.pending = true;
    try { await matchShootNow(); } finally { B.match.pending = false; }
  }

  async function matchShootNow() {
    cancelAnim();
    S.cloud = null;
    const r = await api("POST", "/api/match/" + S.match.id + "/shot", { action: currentAction() });
    await playShots(r.shots);
    showMatch(r.state);
    S.balls = r.state.positions.map((p) => p.slice());
    S.shooter = 0;
    S.played = null;
    showAim();
    draw();
    status(r.state.over ? "the match is over" : "your shot");
  }

  // ------------------------------------------------------------------ input

  function canvasPoint(e) {
    const c = $("table"), rect = c.getBoundingClientRect();
    return geom().inv((e.clientX - rect.left) * c.width / rect.width, (e.clientY - rect.top) * c.height / rect.height);
  }

  function aimAt(p) {
    const from = S.balls[S.shooter];
    if (Math.hypot(p[0] - from[0], p[1] - from[1]) < 1e-6) return;
    S.aim.theta = Math.atan2(p[1] - from[1], p[0] - from[0]);
    if (S.aim.theta < 0) S.aim.theta += 2 * Math.PI;
    showAim();
  }

  function canAim() {
    if (B.view === "lab") return true;
    return B.view === "play" && S.match && !S.match.over && S.match.to_play === "human" && (!S.anim || S.anim.state === "done");
  }

  function onDown(e) {
    if (!canAim()) return;
    if (S.anim && S.anim.state === "done") { S.anim = null; B.anim.state = "idle"; }
    const p = canvasPoint(e), R = S.table.ball_radius;
    if (B.view === "lab") {
      const k = S.balls.findIndex((b) => Math.hypot(b[0] - p[0], b[1] - p[1]) < 1.4 * R);
      if (k >= 0) {
        S.drag = { kind: "ball", k };
        S.balls = S.balls.map((b) => b.slice());
        S.labBalls = S.balls;
        S.cloud = null;
        return;
      }
    }
    S.drag = { kind: "aim" };
    aimAt(p);
    draw();
  }

  function onMove(e) {
    if (!S.drag) return;
    const p = canvasPoint(e), R = S.table.ball_radius, t = S.table;
    if (S.drag.kind === "ball") {
      S.balls[S.drag.k] = [Math.min(Math.max(p[0], R), t.table_width - R), Math.min(Math.max(p[1], R), t.table_length - R)];
    } else aimAt(p);
    draw();
  }

  function onUp() {
    if (!S.drag) return;
    S.drag = null;
    draw();
    requestPreview();
  }

  function onTipClick(e) {
    const c = $("tip"), rect = c.getBoundingClientRect(), r = 46 * (S.table ? S.table.max_english : 1);
    const x = (e.clientX - rect.left) * c.width / rect.width - c.width / 2, y = (e.clientY - rect.top) * c.height / rect.height - c.height / 2;
    let a = -x / r, b = -y / r;
    const n = Math.hypot(a, b);
    if (n > 1) { a /= n; b /= n; }
    S.aim.a = Math.round(a * 100) / 100;
    S.aim.b = Math.round(b * 100) / 100;
    S.played = null;
    showAim();
    requestPreview();
    draw();
  }

  function readInputs() {
    const th = Number($("in-theta").value), a = Number($("in-a").value), b = Number($("in-b").value);
    if (Number.isFinite(th)) S.aim.theta = ((th % 360) + 360) % 360 * Math.PI / 180;
    S.aim.p = Number($("in-power").value);
    if (Number.isFinite(a)) S.aim.a = Math.max(-1, Math.min(1, a));
    if (Number.isFinite(b)) S.aim.b = Math.max(-1, Math.min(1, b));
    $("power-val").textContent = fmt(S.aim.p, 2);
    S.played = null;
    drawTip();
    draw();
    requestPreview();
  }

  function fillSelect(sel, values, labels) {
    sel.innerHTML = "";
    values.forEach((v, i) => {
      const o = document.createElement("option");
      o.value = v;
      o.textContent = labels ? labels[i] : v;
      sel.appendChild(o);
    });
  }

  function wire() {
    for (const b of document.querySelectorAll("#tabs button")) b.addEventListener("click", () => setView(b.dataset.view));
    const c = $("table");
    c.addEventListener("mousedown", onDown);
    window.addEventListener("mousemove", onMove);
    window.addEventListener("mouseup", onUp);
    $("tip").addEventListener("click", onTipClick);
    for (const id of ["in-theta", "in-power", "in-a", "in-b"]) $(id).addEventListener("input", readInputs);
    $("speed").addEventListener("change", () => { S.speed = Number($("speed").value); });
    $("scrub").addEventListener("input", () => {
      const a = S.anim, f = Number($("scrub").value) / 1000;
      if (!a) return;
      setPlaying(false);
      a.t = a.duration * f;
      if (a.state === "done" && a.t < a.duration) { a.state = "running"; a.last = null; requestAnimationFrame(tick); }
      updateClock();
      draw();
    });
    $("btn-play").addEventListener("click", guard(async () => {
      if (S.playing) { setPlaying(false); return; }
      const a = S.anim;
      if (a && a.state === "running") { a.last = null; setPlaying(true); return; }
      if (B.view === "replay") {
        if (!S.unit) { status("choose a run first", true); return; }
        const next = S.index < 0 || (a && a.state === "done") ? S.index + 1 : S.index;
        await showShot(next >= S.unit.shots.length ? 0 : next, true);
      } else if (a && a.shot) {  // the last shot again
        const ended = animate(a.shot);
        setPlaying(true);
        await ended;
      }
    }));
    $("btn-end").addEventListener("click", () => {
      const a = S.anim;
      if (a && a.state === "running") { a.t = a.duration; if (!S.playing) finish(); }
    });
    $("btn-prev").addEventListener("click", guard(() => showShot(S.index - 1, S.playing)));
    $("btn-next").addEventListener("click", guard(() => showShot(S.index + 1, S.playing)));
    $("run-select").addEventListener("change", guard(() => openRun($("run-select").value)));
    $("unit-select").addEventListener("change", guard(() => openUnit($("unit-select").value)));
    $("btn-shoot").addEventListener("click", guard(() => (B.view === "play" ? matchShoot() : labShoot(false))));
    $("btn-ask").addEventListener("click", guard(() => askAgent(false)));
    $("btn-hint").addEventListener("click", guard(() => askAgent(true)));
    $("btn-start").addEventListener("click", guard(startMatch));
    $("btn-rack").addEventListener("click", () => {
      cancelAnim();
      S.labBalls = S.table.opening_rack.map((p) => p.slice());
      S.balls = S.labBalls;
      S.cloud = null;
      draw();
      requestPreview();
    });
    $("btn-undo").addEventListener("click", () => {
      if (!S.before) return;
      cancelAnim();
      S.labBalls = S.before.map((p) => p.slice());
      S.balls = S.labBalls;
      draw();
      requestPreview();
    });
    $("lab-physics").addEventListener("change", () => {
      cancelAnim();
      setTable($("lab-physics").value);
      S.labBalls = S.table.opening_rack.map((p) => p.slice());
      S.balls = S.labBalls;
      showAim();
      draw();
      requestPreview();
    });
    $("lab-preview").addEventListener("change", () => { requestPreview(); draw(); });
    $("rp-considered").addEventListener("change", () => {
      if (S.unit && S.index >= 0 && !(S.considered && S.considered.index === S.index)) loadConsidered(S.index, S.replayToken);
      if (!$("rp-considered").checked) showConsidered(null);
      else if (S.considered && S.considered.index === S.index) showConsidered(S.considered.data);
      draw();
    });
  }

  async function init() {
    wire();
    S.config = await api("GET", "/api/config");
    const physics = Object.keys(S.config.physics), noise = Object.keys(S.config.noise);
    fillSelect($("lab-physics"), physics);
    fillSelect($("lab-noise"), noise);
    fillSelect($("play-noise"), noise);
    $("play-noise").value = "fastfiz_x5";
    const specs = Object.keys(S.config.agents);
    fillSelect($("agent-select"), specs, specs.map((s) => s + " \u2014 " + S.config.agents[s].note));
    $("agent-select").value = "search:h2";
    fillSelect($("hint-select"), specs);
    $("hint-select").value = "search:default";
    fillSelect($("play-opponent"), S.config.opponents);
    $("play-opponent").value = S.config.opponents.includes("greedy") ? "greedy" : S.config.opponents[0];
    setTable(S.config.default_physics);
    S.balls = S.table.opening_rack.map((p) => p.slice());
    showAim();
    draw();
    const n = await loadRuns();
    status("ready: " + n + " recorded runs");
    B.ready = true;
  }

  window.addEventListener("load", guard(init));
})();
