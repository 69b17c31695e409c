// coassist play: draws the live loop and turns a pointer, a touch or a gamepad into the hand.
// The control loop runs on the server at 125 Hz; this page only draws frames and sends where the hand is.
"use strict";
(() => {
  const COLOR = { path: "#1f77b4", pred: "#ff7f0e", obstacle: "#7f7f7f", target: "#2ca02c", force: "#d62728",
                  tool: "#111111", hand: "#9467bd", grid: "#eeeeee" };
  const EXPLAIN = {
    manual: "Manual guidance: the robot only renders its inertia and damping; all the work is yours (eq. 5.5).",
    impedance: "Impedance control: a spring pulls the tool back onto the plan, so it pushes against you around the obstacle (eq. 5.4).",
    cooperative: "Assistive: a cooperative game shares the effort toward where the robot expects you to go (eq. 3.27–3.31).",
    "manual-probe": "Calibration, no assistance: manual guidance plus a small known push that measures your arm (coassist calibrate fits these trials).",
  };
  // the probe is a calibration trial, never an assistive condition: its name says so
  const NAMES = { manual: "manual guidance (MG)", impedance: "impedance control (IMP)", cooperative: "assistive (cooperative game)",
                  "cooperative-arbitrated": "assistive, α arbitrated online",
                  "cooperative-damped": "assistive, α arbitrated, damped while slowing",
                  "manual-probe": "calibration: MG + probe (no assistance)" };
  const FORCE_PX_PER_N = 3;   // arrow length
  const GAMEPAD_REACH = 0.08; // [m] hand offset at full stick deflection (≈ 32 N with the default spring)
  const HEARTBEAT_MS = 50;    // while held, the hand is re-sent: the server lets go after 0.25 s of silence

  const canvas = document.getElementById("view");
  let ctx = canvas.getContext("2d");
  const $ = (id) => document.getElementById(id);
  const api = window.coassist = { ready: false, role: null, frames: 0, draws: 0, fps: 0, latencies: [], pongs: [],
                                  frame: null, scene: null, results: [], summary: {}, running: false, lastDrawSeq: -1, stages: [] };
  const token = new URLSearchParams(location.search).get("token") || "";
  let ws = null, bounds = null, view = null;
  let seq = 0;
  const pending = new Map();  // pointer seq → [input event's time, sent, frame received] (performance.now() clock)
  const pings = new Map();
  const hand = { x: 0, y: 0, down: false };
  let padActive = false, lastDrawn = null;

  // ------------------------------------------------------------------ link
  function connect() {
    const proto = location.protocol === "https:" ? "wss:" : "ws:";
    ws = new WebSocket(`${proto}//${location.host}/ws` + (token ? `?token=${encodeURIComponent(token)}` : ""));
    ws.onmessage = (ev) => onMessage(JSON.parse(ev.data));
    ws.onclose = () => {
      api.ready = false;
      setStatus("disconnected from the server — retrying…", "warn");
      setTimeout(connect, 1000);
    };
  }
  function send(obj) { if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(obj)); }
  api.send = send;
  api.startName = null;  // a study names the step's condition (its label) instead of the picked controller
  function sendHand(eventTime) {
    seq += 1;
    if (eventTime !== null) {
      pending.set(seq, [eventTime, performance.now(), null]);
      if (pending.size > 4096) pending.delete(pending.keys().next().value);
    }
    send({ type: "pointer", x: hand.x, y: hand.y, down: hand.down, seq });
  }
  api.ping = (n) => { seq += 1; pings.set(seq, performance.now()); send({ type: "ping", seq }); return seq; };
  api.untimed = () => Array.from(pending.keys());  // pointer events no drawn frame has answered yet (their seqs)
  setInterval(() => { if (hand.down) sendHand(null); }, HEARTBEAT_MS);

  function onMessage(m) {
    if (m.type === "init") {
      bounds = m.bounds; api.role = m.role; layout();
      const sel = $("controller"); sel.innerHTML = "";
      for (const c of m.controllers) { const o = document.createElement("option"); o.value = c; o.textContent = NAMES[c] || c; sel.appendChild(o); }
      if (m.controller) sel.value = m.controller;
      explain();
      $("s-model").textContent = m.model ? m.model : "none (the plan)";
      $("folder").textContent = `Trials are saved in ${m.folder} (user ${m.user}). Train on them: coassist train ${m.folder} --out <model>`;
      api.results = m.results; api.summary = m.summary; renderResults();
      api.scene = m.scene; api.running = m.running; api.frame = null;
      setRunning(m.running);
      api.ready = true;
      api.mode = m.mode;
      setStatus(m.mode === "monitor" ? "monitoring a coassist drive run (read-only)"
                : m.role === "hand" ? (m.running ? "a trial is running — grab the tool" : "ready: pick a controller and start a trial")
                : "watching (another page is the hand)", "");
    } else if (m.type === "started") {
      if (m.bounds) { bounds = m.bounds; layout(); }
      api.scene = m.scene; api.frame = null; setRunning(true);
      setStatus(`trial ${m.scene.index + 1} (${m.scene.task}) with ${NAMES[m.controller] || m.controller}: follow the plan, avoid the box, hold in the target`, "");
    } else if (m.type === "frame") {
      api.frame = m; api.frames += 1;
      const now = performance.now();
      for (const [s, p] of pending) { if (s > m.seq) break; if (p[2] === null) p[2] = now; }
      if (api.frames % 10 === 0) { $("s-dropped").textContent = m.dropped; $("s-miss").textContent = m.misses; $("s-trial").textContent = `${m.index + 1} · ${m.t.toFixed(1)} s`; }
    } else if (m.type === "result") {
      const r = m.result; api.results.push(r); api.summary = m.summary; api.scene = m.next; api.frame = null;
      setRunning(false); renderResults();
      const sig = r.sigma === null ? "target not reached" : `σ ${(1000 * r.sigma).toFixed(1)} mm`;
      setStatus(`trial ${r.index + 1} saved (${r.file}): f_RMS ${r.f_rms.toFixed(2)} N, ${sig}, ended: ${r.ended}`, "");
    } else if (m.type === "status") {
      if (m.level !== "") { setRunning(false); api.frame = null; }
      setStatus(m.text, m.level);
    } else if (m.type === "pong") {
      const t0 = pings.get(m.seq); pings.delete(m.seq);
      if (t0 !== undefined) api.pongs.push(performance.now() - t0);
    }
    if (api.extend) api.extend(m);  // a study's own messages and its view of the others (study.js)
  }

  // ------------------------------------------------------------------ page
  function setStatus(text, level) { const s = $("status"); s.textContent = text; s.className = level || ""; }
  function setRunning(on) { api.running = on; $("start").disabled = on || api.role !== "hand"; $("abort").disabled = !on || api.role !== "hand"; }
  function explain() { $("explain").textContent = EXPLAIN[$("controller").value] || ""; }
  $("controller").addEventListener("change", explain);
  $("start").addEventListener("click", () => send({ type: "start", controller: api.startName || $("controller").value }));
  $("abort").addEventListener("click", () => send({ type: "abort" }));
  function renderResults() {
    const body = $("results").querySelector("tbody"); body.innerHTML = "";
    for (const r of api.results) {
      const tr = document.createElement("tr");
      tr.innerHTML = `<td>${r.index + 1}</td><td>${r.task}</td><td>${r.controller}</td><td>${r.f_rms.toFixed(2)}</td>` +
                     `<td>${r.sigma === null ? "—" : (1000 * r.sigma).toFixed(1)}</td><td>${r.ended}</td>`;
      body.appendChild(tr);
    }
    const sb = $("summary").querySelector("tbody"); sb.innerHTML = "";
    for (const [c, s] of Object.entries(api.summary)) {
      const tr = document.createElement("tr");
      tr.innerHTML = `<td>${NAMES[c] || c}</td><td>${s.trials}</td><td>${s.f_rms.toFixed(2)}</td><td>${s.sigma === null ? "—" : (1000 * s.sigma).toFixed(1)}</td>`;
      sb.appendChild(tr);
    }
  }

  // ------------------------------------------------------------------ view: metres ↔ canvas pixels (x right, y up)
  function layout() {
    const [x0, x1, y0, y1] = bounds;
    const s = Math.min(canvas.width / (x1 - x0), canvas.height / (y1 - y0));
    view = { s, ox: (canvas.width - s * (x1 - x0)) / 2 - s * x0, oy: (canvas.height - s * (y1 - y0)) / 2 + s * y1 };
  }
  const px = (x, y) => [view.ox + view.s * x, view.oy - view.s * y];
  function toWorld(ev) {
    const r = canvas.getBoundingClientRect();
    const cx = (ev.clientX - r.left) * canvas.width / r.width, cy = (ev.clientY - r.top) * canvas.height / r.height;
    const [x0, x1, y0, y1] = bounds;
    return [Math.min(x1, Math.max(x0, (cx - view.ox) / view.s)), Math.min(y1, Math.max(y0, (view.oy - cy) / view.s))];
  }
  api.toPixels = (x, y) => { const r = canvas.getBoundingClientRect(); const [a, b] = px(x, y); return [r.left + a * r.width / canvas.width, r.top + b * r.height / canvas.height]; };

  // ------------------------------------------------------------------ the hand: pointer (mouse, touch, pen) and gamepad
  canvas.addEventListener("pointerdown", (ev) => {
    if (!view) return;
    canvas.setPointerCapture(ev.pointerId);
    [hand.x, hand.y] = toWorld(ev); hand.down = true; sendHand(ev.timeStamp); ev.preventDefault();
  });
  // pointerrawupdate (Chromium, secure contexts such as 127.0.0.1) arrives as soon as the input does;
  // pointermove is held back to the next animation frame (up to 16 ms later).
  const MOVE = "onpointerrawupdate" in window ? "pointerrawupdate" : "pointermove";
  // A 1000 Hz mouse would flood the link: at most one message per 4 ms, the last position always sent.
  let lastMove = -1e9, trailing = null;
  canvas.addEventListener(MOVE, (ev) => {
    if (!view || !hand.down) return;
    [hand.x, hand.y] = toWorld(ev);
    const now = performance.now();
    if (now - lastMove >= 4) { lastMove = now; sendHand(ev.timeStamp); return; }
    if (trailing === null) {
      const t = ev.timeStamp;
      trailing = setTimeout(() => { trailing = null; if (hand.down) { lastMove = performance.now(); sendHand(t); } }, 4);
    }
  });
  const letGo = (ev) => { if (hand.down) { hand.down = false; sendHand(ev.timeStamp); } };
  canvas.addEventListener("pointerup", letGo);
  canvas.addEventListener("pointercancel", letGo);
  window.addEventListener("blur", () => { if (hand.down) { hand.down = false; sendHand(null); } });

  function gamepad(now) {
    const pads = navigator.getGamepads ? navigator.getGamepads() : [];
    for (const p of pads) {
      if (!p) continue;
      const held = p.buttons.length > 0 && p.buttons[0].pressed;
      if (held && bounds) {
        const base = api.frame ? [api.frame.x, api.frame.y] : (api.scene ? api.scene.start : [0, 0]);
        const [x0, x1, y0, y1] = bounds;
        hand.x = Math.min(x1, Math.max(x0, base[0] + GAMEPAD_REACH * (p.axes[0] || 0)));
        hand.y = Math.min(y1, Math.max(y0, base[1] - GAMEPAD_REACH * (p.axes[1] || 0)));
        hand.down = true; padActive = true; sendHand(now);
      } else if (padActive) { hand.down = false; padActive = false; sendHand(now); }
      return;
    }
  }

  // ------------------------------------------------------------------ drawing, once per display frame
  function line(points, color, width) {
    ctx.strokeStyle = color; ctx.lineWidth = width; ctx.beginPath();
    points.forEach(([x, y], i) => { const [a, b] = px(x, y); if (i === 0) ctx.moveTo(a, b); else ctx.lineTo(a, b); });
    ctx.stroke();
  }
  function disc(x, y, r, fill, stroke, width) {
    const [a, b] = px(x, y); ctx.beginPath(); ctx.arc(a, b, r, 0, 2 * Math.PI);
    if (fill) { ctx.fillStyle = fill; ctx.fill(); }
    if (stroke) { ctx.strokeStyle = stroke; ctx.lineWidth = width || 2; ctx.stroke(); }
  }
  function arrow(x, y, fx, fy) {
    const [a, b] = px(x, y), dx = FORCE_PX_PER_N * fx, dy = -FORCE_PX_PER_N * fy, n = Math.hypot(dx, dy);
    if (n < 2) return;
    const ux = dx / n, uy = dy / n, ex = a + dx, ey = b + dy;
    ctx.strokeStyle = COLOR.force; ctx.fillStyle = COLOR.force; ctx.lineWidth = 4;
    ctx.beginPath(); ctx.moveTo(a, b); ctx.lineTo(ex - 8 * ux, ey - 8 * uy); ctx.stroke();
    ctx.beginPath(); ctx.moveTo(ex, ey); ctx.lineTo(ex - 14 * ux - 7 * uy, ey - 14 * uy + 7 * ux);
    ctx.lineTo(ex - 14 * ux + 7 * uy, ey - 14 * uy - 7 * ux); ctx.closePath(); ctx.fill();
  }
  // What does not move (grid, obstacle, path, target) is drawn once per scene onto an offscreen canvas.
  const still = document.createElement("canvas");
  let stillScene = null;
  function drawStill(sc) {
    still.width = canvas.width; still.height = canvas.height;
    const main = ctx; const c = still.getContext("2d");
    c.fillStyle = "#ffffff"; c.fillRect(0, 0, still.width, still.height);
    c.strokeStyle = COLOR.grid; c.lineWidth = 1; c.beginPath();
    for (let g = Math.ceil(bounds[0] / 0.05) * 0.05; g <= bounds[1]; g += 0.05) { const [a] = px(g, 0); c.moveTo(a, 0); c.lineTo(a, still.height); }
    for (let g = Math.ceil(bounds[2] / 0.05) * 0.05; g <= bounds[3]; g += 0.05) { const [, b] = px(0, g); c.moveTo(0, b); c.lineTo(still.width, b); }
    c.stroke();
    const o = sc.obstacle, [ox, oy] = px(o.center[0] - o.size[0] / 2, o.center[1] + o.size[1] / 2);
    c.fillStyle = COLOR.obstacle; c.fillRect(ox, oy, o.size[0] * view.s, o.size[1] * view.s);
    ctx = c;
    line(sc.path, COLOR.path, 4);
    disc(sc.target[0], sc.target[1], sc.arrive_radius * view.s, "rgba(44,160,44,0.15)", COLOR.target, 3);
    ctx = main;
    stillScene = sc;
  }
  function draw() {
    if (!view || !api.scene) { ctx.fillStyle = "#ffffff"; ctx.fillRect(0, 0, canvas.width, canvas.height); return; }
    const sc = api.scene, f = api.frame;
    if (stillScene !== sc) drawStill(sc);
    ctx.drawImage(still, 0, 0);
    const tool = f ? [f.x, f.y] : sc.start;
    if (f) {
      disc(f.ref[0], f.ref[1], 7, null, COLOR.path, 2);
      line([tool].concat(f.prediction), COLOR.pred, 4);
      if (f.held) {
        const [a, b] = px(tool[0], tool[1]), [c, d] = px(hand.x, hand.y);
        ctx.setLineDash([5, 4]); ctx.strokeStyle = COLOR.hand; ctx.lineWidth = 1.5;
        ctx.beginPath(); ctx.moveTo(a, b); ctx.lineTo(c, d); ctx.stroke(); ctx.setLineDash([]);
      }
    }
    if (hand.down) disc(hand.x, hand.y, 6, null, COLOR.hand, 2);
    disc(tool[0], tool[1], 9, COLOR.tool, null);
    if (f) arrow(tool[0], tool[1], f.fh[0], f.fh[1]);
    $("hud-controller").textContent = f ? (NAMES[f.controller] || f.controller) : (api.running ? "starting…" : `next: ${sc.task} path` + (sc.way ? ` — go round the box on the ${sc.way} (seen along the path)` : ""));
    $("hud-faults").textContent = f && f.faults.length ? "faults: " + f.faults.join(", ") : "";
  }

  let fpsStart = performance.now(), fpsCount = 0;
  function loop(now) {
    requestAnimationFrame(loop);
    gamepad(now);
    draw();
    api.draws += 1; fpsCount += 1;
    const f = api.frame;
    if (f && f !== lastDrawn) {  // a new state is on the screen: time the pointer events it answers
      lastDrawn = f; api.lastDrawSeq = f.seq;
      const t = performance.now();
      for (const [s, p] of pending) {
        if (s > f.seq) break;
        api.latencies.push(t - p[0]); pending.delete(s);
        api.stages.push([p[1] - p[0], (p[2] === null ? t : p[2]) - p[0]]);  // event → sent, event → frame received
      }
      if (api.latencies.length > 5000) { api.latencies.splice(0, 1000); api.stages.splice(0, 1000); }
    }
    if (now - fpsStart >= 1000) {
      api.fps = (1000 * fpsCount) / (now - fpsStart); fpsStart = now; fpsCount = 0;
      $("s-fps").textContent = api.fps.toFixed(0);
      const l = api.latencies.slice(-200).sort((a, b) => a - b);
      if (l.length) $("s-lat").textContent = `${l[Math.floor(l.length / 2)].toFixed(0)} ms`;
    }
  }
  // Connect once every script of the page has run: a message that arrives while the parser still waits for a
  // later script (study.js on a loaded server) would reach no handler of it, and a study's view is sent once.
  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", connect);
  else connect();
  requestAnimationFrame(loop);
})();
