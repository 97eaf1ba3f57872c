// sagu viewer: the page of `python -m billiards.web` (docs/viewer.md). Plain JavaScript, no build step,
// nothing loaded from elsewhere. Three views share one table canvas and one shot panel:
//   replay  -- a recorded run's shots (GET /api/runs, /api/run), each played again exactly by POST /api/shot, and for a
//              search what it considered (POST /api/considered, asked per shot when the shot is shown);
//   lab     -- drag balls, aim, shoot (POST /api/shot), ask an agent (POST /api/agent), undo;
//   play    -- a match against a league player (POST /api/match, /api/match/{id}/shot, GET /api/match/{id}), kept by the
//              server on disk: the page's address names it (#match=<id>), so a reload or a server restart resumes it.
// The address names what is shown (#match=<id>, #run=<path>&unit=<id>&shot=<k>, #view=lab): a link opens it again.
// Input: pointer events (mouse, pen and touch alike); the table takes keyboard focus (arrows aim and set the power).
// What the page shows is also exposed on window.billiards (and the canvas's data-final attribute) for tests.
"use strict";
(function () {
  const $ = (id) => document.getElementById(id);
  const BALL_COLORS = ["#f7f7f2", "#f2c400", "#d7261e", "#9c0d2b"];
  const BALL_EDGES = ["#222", "#222", "#fff", "#fff"];
  const CLOTH = "#1f6e43", RAIL = "#5a3a1e", DIAMOND = "#e8e0c8", RAIL_W = 0.12;
  const PULL = 0.35;  // metres of pull-back behind the cue ball for full power
  const AGENT_COLOR = "#3fd5ff";

  // what tests and people can read: the view, the last shot's end, the replay's and the match's progress
  const B = window.billiards = {
    ready: false, view: "replay", errors: [], busy: 0, aim: null, address: "",
    anim: { state: "idle", t: 0, duration: 0, fps: null, frames: 0, wall: 0 },
    last: null,
    replay: { path: null, unit: null, index: -1, count: 0, finals: {}, frames: {}, done: false, considered: {}, check: null, scores: null },
    lab: { shots: 0, final: null, agent: null, undo: 0 },
    match: { state: null, shots: 0, finals: [], over: false, pending: false, turns: 0, starts: 0, shotRequests: 0 },
    simulator: null,
  };

  const S = {
    config: null, physics: null, table: null,  // the table: set from /api/config's default_physics
    balls: null, before: null,
    aim: { theta: Math.PI / 2, p: 0.5, a: 0, b: 0 }, played: null, shooter: 0,
    anim: null, playing: false, speed: 1,
    preview: null, previewToken: 0, previewTimer: null, cloud: null,
    shown: null, drag: null, tipDrag: false, tipHover: null,
    run: null, unit: null, index: -1, replayToken: 0, shotCache: new Map(), considered: null, consideredCache: new Map(),
    match: null, myAim: null, lastShots: [], agentShot: null, undo: [], inflight: new Map(), nextRequest: 0,
  };

  // ------------------------------------------------------------------ the server

  // one request; its error carries the server's sentence and status. `quiet`: no "working" sign (previews, polling)
  async function api(method, url, body, quiet) {
    const opts = { method, headers: {} };
    if (body !== undefined) {
      opts.headers["content-type"] = "application/json";
      opts.body = JSON.stringify(body);
    }
    const id = ++S.nextRequest;
    B.busy++;
    if (!quiet) S.inflight.set(id, performance.now());
    try {
      const r = await fetch(url, opts);
      let data = null;
      try { data = await r.json(); } catch (e) { data = null; }
      if (!r.ok) {
        const err = new Error((data && typeof data.error === "string" && data.error) || (r.status + " " + r.statusText));
        err.status = r.status;
        throw err;
      }
      return data;
    } finally {
      B.busy--;
      S.inflight.delete(id);
      showBusy();
    }
  }

  // a request that has taken longer than 0.4 s says so: a spinner in the header and over the table, with the seconds
  function showBusy() {
    let oldest = null;
    for (const t of S.inflight.values()) oldest = oldest === null ? t : Math.min(oldest, t);
    const waited = oldest === null ? 0 : (performance.now() - oldest) / 1000;
    const on = oldest !== null && waited > 0.4;
    const preparing = B.simulator && !B.simulator.ready;
    const text = (preparing ? "preparing the simulator" : "working") + " ... " + Math.floor(waited) + " s";
    $("busy").classList.toggle("hidden", !on);
    $("busy-text").textContent = text;
    $("table-wait").classList.toggle("hidden", !on);
    $("table-wait-text").textContent = text;
    $("table-pane").classList.toggle("waiting", on);
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

  // ------------------------------------------------------------------ the address

  function readAddress() {
    const h = new URLSearchParams(location.hash.replace(/^#/, "")), q = new URLSearchParams(location.search);
    return { match: h.get("match") || q.get("match"), run: h.get("run") || q.get("run"), unit: h.get("unit") || q.get("unit"),
      shot: h.get("shot") || q.get("shot"), view: h.get("view") || q.get("view") };
  }

  function setAddress(params) {
    const parts = Object.entries(params).filter(([, v]) => v !== null && v !== undefined && v !== "")
      .map(([k, v]) => k + "=" + encodeURIComponent(String(v)).replace(/%2F/g, "/"));
    const url = location.pathname + (parts.length ? "#" + parts.join("&") : "");
    if (location.pathname + location.search + location.hash !== url) history.replaceState(null, "", url);
    B.address = parts.join("&");
    for (const id of ["shot-link", "match-link"]) $(id).href = location.href;
  }

  // ------------------------------------------------------------------ geometry and drawing

  // a point of the table (metres) where it is on the screen (CSS pixels of the viewport): for tests and touch helpers
  B.toScreen = (xy) => {
    const c = $("table"), r = c.getBoundingClientRect(), g = geom();
    return [r.left + g.X(xy[0]) * r.width / c.width, r.top + g.Y(xy[1]) * r.height / c.height];
  };

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

  // where the cue ball sent along theta first touches something: another ball (its centre 2R away: the ghost ball)
  // or a cushion (its centre R from the rail); straight lines, no spin: a guide, not the simulator
  function aimGuide(from, theta) {
    const R = S.table.ball_radius, W = S.table.table_width, L = S.table.table_length;
    const dx = Math.cos(theta), dy = Math.sin(theta);
    let best = { t: Infinity };
    S.balls.forEach((b, k) => {
      if (k === S.shooter) return;
      const fx = b[0] - from[0], fy = b[1] - from[1], along = fx * dx + fy * dy;
      if (along <= 0) return;
      const off2 = fx * fx + fy * fy - along * along, r2 = 4 * R * R;
      if (off2 > r2) return;
      const t = along - Math.sqrt(r2 - off2);
      if (t >= 0 && t < best.t) best = { t, kind: "ball", ball: k };
    });
    for (const [d, lo, hi, axis] of [[dx, R, W - R, 0], [dy, R, L - R, 1]]) {
      if (Math.abs(d) < 1e-12) continue;
      const t = ((d > 0 ? hi : lo) - from[axis]) / d;
      if (t >= 0 && t < best.t) best = { t, kind: "cushion", axis };
    }
    if (!Number.isFinite(best.t)) return null;
    const at = [from[0] + best.t * dx, from[1] + best.t * dy];
    if (best.kind === "ball") {
      const b = S.balls[best.ball], n = Math.hypot(b[0] - at[0], b[1] - at[1]) || 1;
      return { kind: "ball", ball: best.ball, at, on: [(b[0] - at[0]) / n, (b[1] - at[1]) / n] };
    }
    return { kind: "cushion", at, on: best.axis === 0 ? [-dx, dy] : [dx, -dy] };
  }

  function drawGuide(ctx, g, from, theta) {
    const guide = aimGuide(from, theta);
    if (!guide) return;
    ctx.save();
    ctx.setLineDash([5, 5]);
    ctx.strokeStyle = "rgba(255,255,255,0.85)";
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    ctx.moveTo(g.X(from[0]), g.Y(from[1]));
    ctx.lineTo(g.X(guide.at[0]), g.Y(guide.at[1]));
    ctx.stroke();
    ctx.setLineDash([]);
    if (guide.kind === "ball") {  // the ghost ball, and where the object ball goes
      ctx.beginPath();
      ctx.arc(g.X(guide.at[0]), g.Y(guide.at[1]), g.R * g.s, 0, 2 * Math.PI);
      ctx.strokeStyle = "rgba(255,255,255,0.9)";
      ctx.stroke();
      const b = S.balls[guide.ball];
      ctx.beginPath();
      ctx.moveTo(g.X(b[0]), g.Y(b[1]));
      ctx.lineTo(g.X(b[0] + 0.25 * guide.on[0]), g.Y(b[1] + 0.25 * guide.on[1]));
      ctx.strokeStyle = BALL_COLORS[guide.ball];
      ctx.lineWidth = 2;
      ctx.stroke();
    } else {  // the first cushion and the reflected line
      ctx.beginPath();
      ctx.moveTo(g.X(guide.at[0]), g.Y(guide.at[1]));
      ctx.lineTo(g.X(guide.at[0] + 0.2 * guide.on[0]), g.Y(guide.at[1] + 0.2 * guide.on[1]));
      ctx.strokeStyle = "rgba(255,255,255,0.5)";
      ctx.stroke();
    }
    ctx.restore();
    B.guide = guide;
  }

  // the cue behind the cue ball, pulled back with the power
  function drawCue(ctx, g, from, theta, p) {
    const back = [-Math.cos(theta), -Math.sin(theta)], gap = g.R * 1.3 + 0.02 + PULL * p, len = 1.0;
    const a = [from[0] + gap * back[0], from[1] + gap * back[1]], b = [from[0] + (gap + len) * back[0], from[1] + (gap + len) * back[1]];
    ctx.save();
    ctx.lineCap = "round";
    ctx.beginPath();
    ctx.moveTo(g.X(a[0]), g.Y(a[1]));
    ctx.lineTo(g.X(b[0]), g.Y(b[1]));
    ctx.strokeStyle = "rgba(0,0,0,0.35)";
    ctx.lineWidth = 8;
    ctx.stroke();
    ctx.strokeStyle = "#d8b071";
    ctx.lineWidth = 5;
    ctx.stroke();
    ctx.beginPath();
    ctx.moveTo(g.X(a[0]), g.Y(a[1]));
    ctx.lineTo(g.X(a[0] + 0.02 * back[0]), g.Y(a[1] + 0.02 * back[1]));
    ctx.strokeStyle = "#3a6fd8";
    ctx.lineWidth = 5;
    ctx.stroke();
    ctx.restore();
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
    B.balls = S.balls;
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
    B.guide = null;
    if (a) {
      const p = a.shot.paths, upto = frameIndex(p.t, a.t);
      for (const k of [1, 2, 3, 0]) drawPath(ctx, g, p.xy, k, upto, 1.6, 0.95);
      drawEvents(ctx, g, a.shot, a.t);
      balls = a.t >= a.duration ? a.shot.final : positionsAt(p, a.t);
      if (a.t === 0) drawShotAim(ctx, g, a.shot);
    } else if (aiming()) {
      const from = S.balls[S.shooter];
      if (S.agentShot) drawAim(ctx, g, from, S.agentShot.action[0], S.agentShot.action[1], AGENT_COLOR, false);
      drawGuide(ctx, g, from, S.aim.theta);
      drawCue(ctx, g, from, S.aim.theta, S.aim.p);
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

  const TIP_R = 46;

  function drawTip() {
    const c = $("tip"), ctx = c.getContext("2d"), cx = c.width / 2, cy = c.height / 2, r = TIP_R;
    const maxE = S.table ? S.table.max_english : 1;
    ctx.clearRect(0, 0, c.width, c.height);
    ctx.beginPath(); ctx.arc(cx, cy, r, 0, 2 * Math.PI);
    ctx.fillStyle = BALL_COLORS[S.shooter]; ctx.fill(); ctx.strokeStyle = "#000"; ctx.lineWidth = 1; ctx.stroke();
    ctx.beginPath(); ctx.arc(cx, cy, r * maxE, 0, 2 * Math.PI);
    ctx.setLineDash([3, 3]); ctx.strokeStyle = "#777"; ctx.stroke(); ctx.setLineDash([]);
    ctx.beginPath(); ctx.moveTo(cx - r, cy); ctx.lineTo(cx + r, cy); ctx.moveTo(cx, cy - r); ctx.lineTo(cx, cy + r);
    ctx.strokeStyle = "rgba(0,0,0,0.15)"; ctx.stroke();
    // seen from behind the cue: a > 0 (left english) is left of centre, b > 0 above
    const spot = (a, b, fill, ring, size) => {
      const n = Math.max(1, Math.hypot(a, b));
      ctx.beginPath(); ctx.arc(cx - (a / n) * r * maxE, cy - (b / n) * r * maxE, size || 5, 0, 2 * Math.PI);
      if (fill) { ctx.fillStyle = fill; ctx.fill(); }
      ctx.strokeStyle = ring; ctx.lineWidth = 2; ctx.stroke();
    };
    B.tipHover = S.tipHover;
    if (S.tipHover && tipEditable()) spot(S.tipHover[0], S.tipHover[1], null, "rgba(31,59,44,0.6)", 7);  // follows the pointer
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
    B.aim = { theta: S.aim.theta, p: S.aim.p, a: S.aim.a, b: S.aim.b };
    drawTip();
  }

  // the action at the shot's start; its outcome only once it has played (describeOutcome)
  function describeAction(shot) {
    const c = shot.commanded, p = shot.played;
    let text = "commanded: \u03b8 " + fmt(deg(c[0]), 2) + "\u00b0, p " + fmt(c[1], 3) + ", a " + fmt(c[2], 2) + ", b " + fmt(c[3], 2);
    if (p && p.some((v, i) => v !== c[i])) {
      text += " | played (noise" + (shot.level !== null && shot.level !== undefined ? ", level " + fmt(shot.level, 2) : "") + "): \u03b8 "
        + fmt(deg(p[0]), 2) + "\u00b0, p " + fmt(p[1], 3) + ", a " + fmt(p[2], 2) + ", b " + fmt(p[3], 2);
    }
    if (shot.caption) text = shot.caption + ". " + text;
    $("action-text").textContent = text;
    const out = $("outcome");
    out.className = "outcome pending";
    out.textContent = (shot.who ? shot.who + ": " : "") + "\u2026 (the outcome shows once the shot has played)";
  }

  function describeOutcome(shot) {
    const r = shot.result, out = $("outcome");
    const hits = Object.entries(r.hits).map(([k, v]) => k + (v ? " \u2713" : " \u2717")).join(", ");
    out.className = "outcome " + r.label;
    out.textContent = r.label.toUpperCase() + (shot.who ? " (" + shot.who + ")" : "") + ": first contact " + (r.first_contact || "none")
      + "; " + hits + "; " + r.cushions + " cushion" + (r.cushions === 1 ? "" : "s") + "; " + fmt(r.duration, 2) + " s";
  }

  function clearShotText() {
    $("outcome").className = "outcome";
    $("outcome").textContent = "";
    $("action-text").textContent = "";
  }

  // the running score above the table (play, and replays whose shots carry scores); null hides it
  function showScores(sb) {
    B.scores = sb;
    $("scorebar").classList.toggle("hidden", !sb);
    if (!sb) return;
    $("sb-white-name").textContent = sb.names[0];
    $("sb-yellow-name").textContent = sb.names[1];
    $("sb-white-score").textContent = fmt(sb.scores[0], 0);
    $("sb-yellow-score").textContent = fmt(sb.scores[1], 0);
    $("sb-middle").textContent = sb.middle || "";
    $("sb-white").classList.toggle("to-play", sb.toPlay === 0);
    $("sb-yellow").classList.toggle("to-play", sb.toPlay === 1);
  }

  // ------------------------------------------------------------------ animation

  // play `shot` (an /api/shot answer) from t = 0; resolves true at its end, false if another shot replaced it
  function animate(shot, onEnd) {
    if (S.anim && S.anim.resolve) S.anim.resolve(false);
    return new Promise((resolve) => {
      S.anim = { shot, t: 0, duration: shot.result.duration, last: null, resolve, frames: 0, wall: 0, state: "running", onEnd };
      S.shown = shot;
      S.aim = { theta: shot.commanded[0], p: shot.commanded[1], a: shot.commanded[2], b: shot.commanded[3] };
      S.played = shot.played && shot.played.some((v, i) => v !== shot.commanded[i]) ? shot.played : null;
      S.shooter = shot.shooter;
      showAim();
      describeAction(shot);
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
    describeOutcome(a.shot);
    if (a.onEnd) a.onEnd(a.shot);
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
    $("keys-note").classList.toggle("hidden", view === "replay");
    for (const id of ["in-theta", "in-power", "in-a", "in-b"]) $(id).disabled = view === "replay";  // a replay's shot is the record's
    cancelAnim();
    S.preview = null;
    S.cloud = null;
    S.played = null;
    S.agentShot = null;
    $("agent-actions").classList.add("hidden");
    $("btn-hint-take").classList.add("hidden");
    clearShotText();
    status("");  // what the other view said (an overlap, a lab shot's outcome) is not this one's
    if (view === "lab") {
      setTable($("lab-physics").value);
      if (!S.labBalls) S.labBalls = S.table.opening_rack.map((p) => p.slice());
      S.balls = S.labBalls;
      S.shooter = 0;
      showScores(null);
      setAddress({ view: "lab" });
      requestPreview();
    } else if (view === "play") {
      setTable(S.match ? S.match.physics : S.config.default_physics);
      S.balls = S.match ? S.match.positions.map((p) => p.slice()) : S.table.opening_rack.map((p) => p.slice());
      S.shooter = 0;
      if (S.match) { showMatch(S.match); beginTurn(); } else showScores(null);
      setAddress(S.match ? { match: S.match.id } : S.wantMatch ? { match: S.wantMatch } : { view: "play" });
      loadResumable().catch(() => {});
    } else {
      setTable(S.run ? S.run.physics : S.physics);
      if (S.unit && S.index >= 0) { S.balls = S.unit.shots[S.index].positions; replayScores(S.index, false); } else showScores(null);
      if (!S.balls) S.balls = S.table.opening_rack.map((p) => p.slice());
      setAddress(S.unit && S.index >= 0 ? { run: S.run.path, unit: S.unit.id, shot: S.index + 1 } : {});
    }
    updateShoot();
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
    S.physics = name || S.config.default_physics;
    S.table = S.config.physics[S.physics] || S.config.physics[S.config.default_physics];
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

  // open a run; then its unit `unitId` (default the first) at shot `shotIndex` (default 0)
  async function openRun(path, unitId, shotIndex) {
    cancelAnim();
    S.run = null; S.unit = null; S.index = -1; S.shotCache.clear(); S.considered = null; S.consideredCache.clear();
    showConsidered(null);
    showScores(null);
    clearShotText();
    Object.assign(B.replay, { path, unit: null, index: -1, count: 0, finals: {}, frames: {}, done: false, considered: {}, check: null, scores: null });
    const us = $("unit-select");
    us.innerHTML = "";
    us.disabled = true;
    $("shot-link").classList.add("hidden");
    if (!path) { setAddress({}); return; }
    if ($("run-select").value !== path) {
      $("run-select").value = path;
      if ($("run-select").value !== path) {  // not in the list (a link to a run the list leaves out): offered all the same
        const o = document.createElement("option");
        o.value = path;
        o.textContent = path;
        $("run-select").appendChild(o);
        $("run-select").value = path;
      }
    }
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
    if (!playable) { setAddress({ run: path }); return; }
    const wanted = unitId !== undefined && unitId !== null && run.units.some((u) => String(u.id) === String(unitId)) ? unitId : run.units[0].id;
    us.value = String(wanted);
    await openUnit(wanted, shotIndex);
  }

  async function openUnit(id, shotIndex) {
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
    const k = Number.isInteger(shotIndex) && shotIndex >= 0 && shotIndex < unit.shots.length ? shotIndex : 0;
    await showShot(k, false);
  }

  // the running score of a replayed unit whose shots carry it (leagues, matches played here, match-track scorecards)
  function replayScores(k, after) {
    const shots = S.unit ? S.unit.shots : null;
    if (!shots || !shots[k] || !Array.isArray(shots[k].scores)) { showScores(null); B.replay.scores = null; return; }
    const rec = S.unit.record || {};
    const names = [rec.a || "white", rec.b || "yellow"];
    const scores = after ? shots[k].scores : k > 0 ? shots[k - 1].scores : [0, 0];
    B.replay.scores = scores.slice();
    showScores({ names, scores, toPlay: shots[k].shooter, middle: "shot " + (k + 1) + " / " + shots.length + (after ? "" : " (before it)") });
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
    setAddress({ run: S.run.path, unit: S.unit.id, shot: k + 1 });
    $("shot-link").classList.remove("hidden");
    replayScores(k, false);
    if (!S.considered || S.considered.index !== k) { S.considered = null; showConsidered(null); }
    loadConsidered(k, token);
    const shot = await shotRequest(k);
    if (token !== S.replayToken) return;
    if (k + 1 < S.unit.shots.length) shotRequest(k + 1).catch(() => {});
    if (play) setPlaying(true);
    const ended = await animate(shot, () => { if (token === S.replayToken) replayScores(k, true); });
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
      const r = await api("POST", "/api/shot", { positions: S.balls, action: currentAction(), physics: S.physics, noise: "none" }, true);
      if (token !== S.previewToken || S.anim) return;
      S.preview = r;
      draw();
    }), 90);
  }

  function overlapsAny(balls) {
    return balls.some((_, k) => overlaps(balls, k));
  }

  // the lab's undo: the balls and the aim before each change of the table (a ball moved, a rack, a shot)
  function pushUndo() {
    S.undo.push({ balls: S.balls.map((p) => p.slice()), aim: Object.assign({}, S.aim) });
    if (S.undo.length > 200) S.undo.shift();
    B.lab.undo = S.undo.length;
    $("btn-undo").disabled = false;
  }

  function undo() {
    if (B.view !== "lab" || !S.undo.length) return;
    cancelAnim();
    const last = S.undo.pop();
    S.lastLabShot = null;
    B.lab.undo = S.undo.length;
    $("btn-undo").disabled = !S.undo.length;
    S.labBalls = last.balls;
    S.balls = S.labBalls;
    S.aim = last.aim;
    S.cloud = null;
    S.played = null;
    clearShotText();
    showAim();
    draw();
    requestPreview();
    status("undone" + (S.undo.length ? " (" + S.undo.length + " more)" : ""));
  }

  // the lab's shot: the shot as set, or `action` (the agent's) without touching the controls
  async function labShoot(action, keepCloud) {
    if (B.lab.pending) return;
    cancelAnim();
    S.previewToken++;
    S.preview = null;
    if (!keepCloud) S.cloud = null;
    const before = S.balls.map((p) => p.slice());
    if (overlapsAny(before)) { status("two balls overlap: move one before shooting", true); draw(); return; }
    const mine = Object.assign({}, S.aim);
    B.lab.pending = true;
    updateShoot();
    let r;
    try {
      r = await api("POST", "/api/shot", { positions: before, action: action || currentAction(), physics: S.physics,
        noise: $("lab-noise").value, seed: Number($("lab-seed").value) || 0 });
    } finally {
      B.lab.pending = false;
      updateShoot();
    }
    S.undo.push({ balls: before, aim: mine });
    B.lab.undo = S.undo.length;
    $("btn-undo").disabled = false;
    S.before = before;
    S.agentShot = null;
    $("agent-actions").classList.add("hidden");
    setPlaying(true);
    status("shot: " + r.result.label);
    const ended = await animate(r);
    if (!ended) return;
    S.labBalls = S.balls;
    Object.assign(B.lab, { shots: B.lab.shots + 1, final: r.final, positions: before, action: r.commanded, played: r.played });
    S.lastLabShot = r;
    setPlaying(false);
    S.aim = mine;  // the person's own shot stands (an agent's shot played from the lab leaves it)
    S.played = null;
    S.anim = null;
    B.anim.state = "idle";
    showAim();
    draw();
  }

  // an agent's shot for the table shown: drawn beside the person's aim (cyan), which it leaves as it is
  async function askAgent(forMatch) {
    const spec = forMatch ? $("hint-select").value : $("agent-select").value;
    const noise = forMatch ? S.match.noise : $("lab-noise").value;
    status("asking " + spec + " ...");
    const r = await api("POST", "/api/agent", { positions: S.balls, agent: spec, physics: S.physics, noise,
      seed: Number($("lab-seed").value) || 0, replays: 50 });
    B.lab.agent = r;
    let text = spec + " answered in " + fmt(1000 * r.seconds, 1) + " ms: \u03b8 " + fmt(deg(r.action[0]), 1) + "\u00b0, p " + fmt(r.action[1], 2)
      + ", a " + fmt(r.action[2], 2) + ", b " + fmt(r.action[3], 2) + " (the cyan line)";
    if (r.sims) text += "; " + r.sims + " simulations";
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
    (forMatch ? $("hint-info") : $("agent-info")).textContent = text;
    S.cloud = r.noisy;
    S.agentShot = { action: r.action, spec };
    if (forMatch) $("btn-hint-take").classList.remove("hidden");
    else $("agent-actions").classList.remove("hidden");
    status(spec + " answered: its shot is the cyan line beside yours");
    draw();
  }

  function takeAgentAim() {
    if (!S.agentShot) return;
    const a = S.agentShot.action;
    S.aim = { theta: a[0], p: a[1], a: a[2], b: a[3] };
    S.played = null;
    showAim();
    draw();
    requestPreview();
  }

  // ------------------------------------------------------------------ play

  function showMatch(state) {
    S.match = state;
    B.match.state = state;
    B.match.over = state.over;
    let text = "to " + state.target + " points, noise " + state.noise + "; innings " + state.innings + ", shots " + state.shots;
    if (state.over) {
      text = (state.winner === "human" ? "You win" : state.winner ? state.opponent + " wins" : "A draw") + " (" + fmt(state.scores.human, 0) + " : "
        + fmt(state.scores[state.opponent], 0) + ")." + (state.saved ? " Saved: " + state.saved : "");
    } else if (state.to_play === "human") text += "; your shot";
    $("match-info").textContent = text;
    $("match-link").classList.remove("hidden");
    $("match-link").textContent = "this match's address (open it again, or after a reload): #match=" + state.id;
    $("btn-rematch").classList.toggle("hidden", !state.over);
    showScores({ names: ["you", state.opponent], scores: [state.scores.human, state.scores[state.opponent]],
      toPlay: state.over ? null : state.to_play === "human" ? 0 : 1,
      middle: state.over ? (state.winner === "human" ? "you win" : state.winner ? state.opponent + " wins" : "a draw") : "to " + state.target });
    updateShoot();
  }

  function myTurn() {
    return B.view === "play" && S.match && !S.match.over && S.match.to_play === "human" && !B.match.pending;
  }

  // shoot and start are locked while a request is in flight (one shot per turn, one match per click)
  function updateShoot() {
    const playing = B.view === "play";
    $("btn-shoot").disabled = playing ? !myTurn() || (S.anim && S.anim.state === "running") : !!B.lab.pending;
    $("btn-start").disabled = B.match.pending;
    $("btn-rematch").disabled = B.match.pending;
    $("btn-resume").disabled = B.match.pending;
    $("btn-hint").disabled = !myTurn();
  }

  function setMatchPending(on) {
    B.match.pending = on;
    updateShoot();
    draw();  // the aim guide and the cue show only while no request is in flight
  }

  // the aim a turn of the person's starts from: at the nearest red, with the person's own last power and tip
  function nearestRedAim() {
    const from = S.balls[0];
    let best = null;
    for (const k of [2, 3]) {
      const d = Math.hypot(S.balls[k][0] - from[0], S.balls[k][1] - from[1]);
      if (best === null || d < best.d) best = { d, k };
    }
    const t = S.balls[best.k];
    let theta = Math.atan2(t[1] - from[1], t[0] - from[0]);
    if (theta < 0) theta += 2 * Math.PI;
    return theta;
  }

  function beginTurn() {
    if (!S.match) return;
    cancelAnim();
    S.balls = S.match.positions.map((p) => p.slice());
    S.shooter = 0;
    S.played = null;
    S.agentShot = null;
    $("btn-hint-take").classList.add("hidden");
    if (!S.match.over && S.match.to_play === "human") {
      const mine = S.myAim || { p: 0.5, a: 0, b: 0 };
      S.aim = { theta: nearestRedAim(), p: mine.p, a: mine.a, b: mine.b };
      B.match.turns++;
    }
    showAim();
    updateShoot();
    draw();
  }

  async function playShots(shots) {
    setPlaying(true);
    for (const s of shots) {
      S.balls = s.positions;
      const ended = await animate(s, () => {
        showScores(Object.assign({}, B.scores, { scores: s.scores, toPlay: null }));
      });
      if (!ended) return false;
      B.match.shots++;
      B.match.finals.push(s.final);
      await new Promise((r) => setTimeout(r, 200 / S.speed));
    }
    setPlaying(false);
    return true;
  }

  function newKey() {
    const a = new Uint8Array(12);
    crypto.getRandomValues(a);
    return Array.from(a, (b) => b.toString(16).padStart(2, "0")).join("");
  }

  async function startMatch(settings) {
    if (B.match.pending) return;  // a second click while the first is answered starts nothing
    setMatchPending(true);
    try { await startMatchNow(settings); } finally { setMatchPending(false); }
  }

  async function startMatchNow(settings) {
    cancelAnim();
    S.cloud = null;
    const body = settings || { opponent: $("play-opponent").value, noise: $("play-noise").value, target: Number($("play-target").value) || 1,
      first: $("play-first").value, seed: Number($("play-seed").value) || 0 };
    body.key = newKey();
    status("starting a match against " + body.opponent + " ...");
    B.match.starts++;
    const r = await api("POST", "/api/match", body);
    Object.assign(B.match, { shots: 0, finals: [], over: false });
    S.myAim = null;  // a new match: the default power and tip until the person shoots
    setTable(r.state.physics);
    setAddress({ match: r.state.id });
    S.balls = r.shots.length ? r.shots[0].positions : r.state.positions;
    const opening = Object.assign({}, r.state, { over: false, to_play: r.shots.length ? r.state.opponent : r.state.to_play,
      scores: { human: 0, [r.state.opponent]: 0 } });
    showMatch(opening);
    draw();
    S.lastShots = r.shots;
    await playShots(r.shots);
    showMatch(r.state);
    beginTurn();
    status("match " + r.state.id + " started: " + (r.state.over ? "over" : "your shot"));
    loadResumable().catch(() => {});
  }

  async function matchShoot() {
    if (!S.match || S.match.over) { status("start a match first", true); return; }
    if (B.match.pending || !myTurn() || (S.anim && S.anim.state === "running")) return;  // one shot per turn
    setMatchPending(true);
    try { await matchShootNow(); } finally { setMatchPending(false); }
  }

  async function matchShootNow() {
    cancelAnim();
    S.cloud = null;
    S.myAim = { p: S.aim.p, a: S.aim.a, b: S.aim.b };
    B.match.shotRequests++;
    let r;
    try {
      r = await api("POST", "/api/match/" + S.match.id + "/shot", { action: currentAction(), turn: S.match.turn });
    } catch (err) {
      if (err.status === 409 || err.status === 404) {  // another tab or a repeated request played it, or it is over: the server's table
        status(err.message, true);
        if (err.status === 409) await resumeMatch(S.match.id, true);
        return;
      }
      throw err;
    }
    S.agentShot = null;
    S.lastShots = r.shots;
    await playShots(r.shots);
    showMatch(r.state);
    beginTurn();
    status(r.state.over ? "the match is over" : "your shot");
    if (r.state.over) loadResumable().catch(() => {});
  }

  // the match `id` as the server holds it (reading it back from disk after a restart): its table, its score, whose turn
  async function resumeMatch(id, keepStatus) {
    const r = await api("GET", "/api/match/" + encodeURIComponent(id));
    setTable(r.state.physics);
    Object.assign(B.match, { over: r.state.over });
    S.lastShots = r.shots || [];
    setAddress({ match: r.state.id });
    showMatch(r.state);
    beginTurn();
    if (!keepStatus) status("match " + r.state.id + " resumed: " + (r.state.over ? "it is over" : r.state.to_play === "human" ? "your shot" : r.state.to_play + " to play"));
    return r.state;
  }

  async function loadResumable() {
    const data = await api("GET", "/api/matches", undefined, true);
    const open = data.matches.filter((m) => !m.over && (!S.match || m.id !== S.match.id));
    fillSelect($("resume-select"), open.map((m) => m.id), open.map((m) => "vs " + m.opponent + " " + fmt(m.scores[0], 0) + ":"
      + fmt(m.scores[1], 0) + " (to " + m.target + "), " + m.id.slice(4, 8) + " " + m.id.slice(9, 11) + ":" + m.id.slice(11, 13)));
    $("resume-row").classList.toggle("hidden", !open.length);
  }

  function rematch() {
    const m = S.match;
    if (!m) return;
    return startMatch({ opponent: m.opponent, noise: m.noise, target: m.target, seed: m.seed + 1,
      first: m.first === "human" ? "agent" : "human", max_innings: m.max_innings });
  }

  // ------------------------------------------------------------------ input

  function canvasPoint(e) {
    const c = $("table"), rect = c.getBoundingClientRect();
    return geom().inv((e.clientX - rect.left) * c.width / rect.width, (e.clientY - rect.top) * c.height / rect.height);
  }

  function cssToMetres(px) {  // a distance on the screen in table metres
    const c = $("table"), rect = c.getBoundingClientRect();
    return px * (c.width / rect.width) / geom().s;
  }

  function aimAt(p) {
    const from = S.balls[S.shooter];
    if (Math.hypot(p[0] - from[0], p[1] - from[1]) < 1e-6) return;
    S.aim.theta = Math.atan2(p[1] - from[1], p[0] - from[0]);
    if (S.aim.theta < 0) S.aim.theta += 2 * Math.PI;
    S.played = null;
    showAim();
  }

  // the cue pulled back: the shot goes away from the pointer, harder the further it is pulled
  function pullCue(p) {
    const from = S.balls[S.shooter], R = S.table.ball_radius;
    const dx = from[0] - p[0], dy = from[1] - p[1], d = Math.hypot(dx, dy);
    if (d < 1.2 * R) return;
    S.aim.theta = Math.atan2(dy, dx);
    if (S.aim.theta < 0) S.aim.theta += 2 * Math.PI;
    S.aim.p = Math.round(100 * Math.min(1, Math.max(0.02, (d - R) / PULL))) / 100;
    S.played = null;
    showAim();
  }

  function aiming() {  // the person is setting up a shot (the aim, the guide and the cue are drawn)
    if (B.view === "lab") return !S.anim;
    return B.view === "play" && S.match && !S.match.over && S.match.to_play === "human" && !S.anim && !B.match.pending;
  }

  function canAim() {
    if (B.view === "lab") return !B.lab.pending;
    return B.view === "play" && S.match && !S.match.over && S.match.to_play === "human" && !B.match.pending
      && (!S.anim || S.anim.state === "done");
  }

  function onDown(e) {
    if (e.button !== undefined && e.button > 0) return;
    $("table").focus({ preventScroll: true });
    if (!canAim()) return;
    e.preventDefault();
    if (S.anim && S.anim.state === "done") { S.anim = null; B.anim.state = "idle"; }
    const p = canvasPoint(e), R = S.table.ball_radius, grab = Math.max(1.3 * R, cssToMetres(12));
    const cue = S.balls[S.shooter], nearCue = Math.hypot(p[0] - cue[0], p[1] - cue[1]) < Math.max(4 * R, cssToMetres(36));
    if (B.view === "lab") {
      const k = S.balls.findIndex((b) => Math.hypot(b[0] - p[0], b[1] - p[1]) < grab);
      if (k >= 0) {
        pushUndo();
        S.drag = { kind: "ball", k };
        S.balls = S.balls.map((b) => b.slice());
        S.labBalls = S.balls;
        S.cloud = null;
        S.preview = null;
        $("table").setPointerCapture(e.pointerId);
        return;
      }
    }
    if (nearCue) S.drag = { kind: "cue" };
    else { S.drag = { kind: "aim" }; aimAt(p); }
    $("table").setPointerCapture(e.pointerId);
    draw();
  }

  function onMove(e) {
    if (!S.drag) return;
    e.preventDefault();
    const p = canvasPoint(e), R = S.table.ball_radius, t = S.table;
    if (S.drag.kind === "ball") {
      S.balls[S.drag.k] = [Math.min(Math.max(p[0], R), t.table_width - R), Math.min(Math.max(p[1], R), t.table_length - R)];
    } else if (S.drag.kind === "cue") pullCue(p);
    else aimAt(p);
    draw();
  }

  function onUp() {
    if (!S.drag) return;
    const was = S.drag;
    S.drag = null;
    if (was.kind === "ball" && $("status").classList.contains("error") && !overlapsAny(S.balls)) status("the balls are apart again");
    draw();
    requestPreview();
  }

  function onKey(e) {
    if (B.view === "lab" && (e.ctrlKey || e.metaKey) && e.key.toLowerCase() === "z") { e.preventDefault(); undo(); return; }
    if (!canAim()) return;
    const step = (e.shiftKey ? 5 : e.altKey ? 0.1 : 0.5) * Math.PI / 180;
    if (e.key === "ArrowLeft" || e.key === "ArrowRight") {
      if (S.anim && S.anim.state === "done") { S.anim = null; B.anim.state = "idle"; }
      S.aim.theta = ((S.aim.theta + (e.key === "ArrowLeft" ? step : -step)) % (2 * Math.PI) + 2 * Math.PI) % (2 * Math.PI);
    } else if (e.key === "ArrowUp" || e.key === "ArrowDown") {
      if (S.anim && S.anim.state === "done") { S.anim = null; B.anim.state = "idle"; }
      S.aim.p = Math.round(100 * Math.min(1, Math.max(0, S.aim.p + (e.key === "ArrowUp" ? 0.02 : -0.02)))) / 100;
    } else if (e.key === "Enter" || e.key === " ") {
      e.preventDefault();
      guard(() => (B.view === "play" ? matchShoot() : labShoot(null, false)))();
      return;
    } else return;
    e.preventDefault();
    S.played = null;
    showAim();
    draw();
    requestPreview();
  }

  function tipEditable() {
    return B.view !== "replay";
  }

  function tipPoint(e) {
    const c = $("tip"), rect = c.getBoundingClientRect(), r = TIP_R * (S.table ? S.table.max_english : 1);
    const x = (e.clientX - rect.left) * c.width / rect.width - c.width / 2, y = (e.clientY - rect.top) * c.height / rect.height - c.height / 2;
    let a = -x / r, b = -y / r;
    const n = Math.hypot(a, b);
    if (n > 1) { a /= n; b /= n; }
    return [Math.round(a * 100) / 100, Math.round(b * 100) / 100];
  }

  function onTipDown(e) {
    if (!tipEditable()) return;
    e.preventDefault();
    S.tipDrag = true;
    $("tip").setPointerCapture(e.pointerId);
    setTip(tipPoint(e));
  }

  function onTipMove(e) {
    if (!tipEditable()) return;
    S.tipHover = tipPoint(e);
    if (S.tipDrag) setTip(S.tipHover);
    else drawTip();
  }

  function setTip(ab) {
    S.aim.a = ab[0];
    S.aim.b = ab[1];
    S.played = null;
    showAim();
    requestPreview();
    draw();
  }

  function readInputs() {
    if (B.view === "replay") return;
    const th = Number($("in-theta").value), a = Number($("in-a").value), b = Number($("in-b").value);
    if (Number.isFinite(th)) S.aim.theta = ((th % 360) + 360) % 360 * Math.PI / 180;
    S.aim.p = Number($("in-power").value);
    if (Number.isFinite(a)) S.aim.a = Math.max(-1, Math.min(1, a));
    if (Number.isFinite(b)) S.aim.b = Math.max(-1, Math.min(1, b));
    $("power-val").textContent = fmt(S.aim.p, 2);
    B.aim = Object.assign({}, S.aim);
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

  // ------------------------------------------------------------------ the simulator's first use

  async function watchSimulator() {
    const s = await api("GET", "/api/simulator", undefined, true);
    B.simulator = s;
    $("sim-expected").textContent = String(s.expected_s);
    $("sim-banner").classList.toggle("hidden", s.ready);
    if (!s.ready) {
      $("sim-elapsed").textContent = "(" + Math.round(s.elapsed_s) + " s so far)";
      setTimeout(guard(watchSimulator), 1000);
    } else if (s.error) status("the simulator could not be prepared: " + s.error, true);
  }

  function wire() {
    for (const b of document.querySelectorAll("#tabs button")) b.addEventListener("click", () => setView(b.dataset.view));
    const c = $("table");
    c.addEventListener("pointerdown", onDown);
    c.addEventListener("pointermove", onMove);
    c.addEventListener("pointerup", onUp);
    c.addEventListener("pointercancel", onUp);
    c.addEventListener("keydown", onKey);
    document.addEventListener("keydown", (e) => {
      if (B.view === "lab" && (e.ctrlKey || e.metaKey) && e.key.toLowerCase() === "z" && e.target === document.body) { e.preventDefault(); undo(); }
    });
    const tip = $("tip");
    tip.addEventListener("pointerdown", onTipDown);
    tip.addEventListener("pointermove", onTipMove);
    tip.addEventListener("pointerup", () => { S.tipDrag = false; });
    tip.addEventListener("pointercancel", () => { S.tipDrag = false; });
    tip.addEventListener("pointerleave", () => { S.tipHover = null; drawTip(); });
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
      } else if (B.view === "play" && S.lastShots.length && !B.match.pending) {  // the last exchange again
        await playShots(S.lastShots);
        beginTurn();
      } else if (B.view === "lab" && S.lastLabShot && !a) {  // the lab's last shot again, then back to its end
        const ended = animate(S.lastLabShot);
        setPlaying(true);
        if (await ended) { S.anim = null; B.anim.state = "idle"; showAim(); draw(); }
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
    $("btn-shoot").addEventListener("click", guard(() => (B.view === "play" ? matchShoot() : labShoot(null, false))));
    $("btn-ask").addEventListener("click", guard(() => askAgent(false)));
    $("btn-agent-play").addEventListener("click", guard(() => S.agentShot && labShoot(S.agentShot.action, true)));
    $("btn-agent-take").addEventListener("click", takeAgentAim);
    $("btn-hint").addEventListener("click", guard(() => askAgent(true)));
    $("btn-hint-take").addEventListener("click", takeAgentAim);
    $("btn-start").addEventListener("click", guard(() => startMatch()));
    $("btn-rematch").addEventListener("click", guard(rematch));
    $("btn-resume").addEventListener("click", guard(async () => {
      const id = $("resume-select").value;
      if (!id || B.match.pending) return;
      setMatchPending(true);
      try { await resumeMatch(id); } finally { setMatchPending(false); }
      loadResumable().catch(() => {});
    }));
    $("btn-rack").addEventListener("click", () => {
      cancelAnim();
      pushUndo();
      S.labBalls = S.table.opening_rack.map((p) => p.slice());
      S.balls = S.labBalls;
      S.cloud = null;
      S.agentShot = null;
      draw();
      requestPreview();
    });
    $("btn-undo").addEventListener("click", undo);
    $("lab-physics").addEventListener("change", () => {
      cancelAnim();
      setTable($("lab-physics").value);
      S.undo = [];
      B.lab.undo = 0;
      $("btn-undo").disabled = true;
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
    window.addEventListener("hashchange", guard(openAddress));
    setInterval(showBusy, 250);
  }

  // what the address names: a match (resumed as the server holds it), a replayed shot, a view
  async function openAddress() {
    const where = readAddress();
    if (where.match) {
      S.wantMatch = where.match;  // the address keeps naming it while it is read (and if the server cannot be reached)
      setView("play");
      if (S.match && S.match.id === where.match) return;
      setMatchPending(true);
      try {
        await resumeMatch(where.match);
      } catch (err) {
        if (err.status === 404) { S.wantMatch = null; S.match = null; setView("play"); }
        throw err;
      } finally { setMatchPending(false); }
    } else if (where.run) {
      setView("replay");
      const shot = where.shot !== null ? Number(where.shot) - 1 : 0;
      await openRun(where.run, where.unit, Number.isInteger(shot) ? shot : 0);
    } else if (where.view === "lab" || where.view === "play") {
      setView(where.view);
    }
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
    watchSimulator().catch(() => {});
    const n = await loadRuns();
    status("ready: " + n + " recorded runs");
    // what the address names, not awaited (a replayed shot waits at its start for ▶): its requests are in flight
    // (window.billiards.busy, match.pending) by the time the page says it is ready
    openAddress().catch((err) => status(String(err.message || err), true));
    B.ready = true;
  }

  window.addEventListener("load", guard(init));
})();
