// Interactive replay of a logged trial (sitframe report). No network, no libraries.
// Data: the JSON in <script id="replay-data">, whose "blob" is base64(gzip(arrays));
// the header says where each quantised array is (typed-array type, byte offset, shape,
// scale: value = stored / scale). See sitframe/analysis/replay_data.py.
(function () {
  "use strict";
  const $ = (id) => document.getElementById(id);
  const root = $("replay");
  if (!root) return;
  const D = JSON.parse($("replay-data").textContent);
  const TYPES = { Uint8Array, Int8Array, Uint16Array, Int16Array, Int32Array };
  const el = {
    trial: $("replay-trial"), episode: $("replay-episode"), play: $("replay-play"),
    speed: $("replay-speed"), trail: $("replay-trail"), slider: $("replay-slider"),
    iter: $("replay-iter"), canvas: $("replay-world"), info: $("replay-info"),
    bars: $("replay-bars"), status: $("replay-status"),
  };
  const angles = D.sensor.angles_deg.map((a) => (a * Math.PI) / 180);
  const maxRange = D.sensor.max_range;
  const R = D.radius;
  let buf = null, ep = null, A = null, i = 0, playing = false, last = 0, acc = 0;

  function view(d) {
    const n = d.shape.reduce((a, b) => a * b, 1);
    return { v: new TYPES[d.type](buf, d.offset, n), s: d.scale, w: d.shape[1] || 1 };
  }
  const at = (a, r, c = 0) => a.v[r * a.w + c] / a.s;

  async function decode() {
    const bin = Uint8Array.from(atob(D.blob), (ch) => ch.charCodeAt(0));
    const stream = new Blob([bin]).stream().pipeThrough(new DecompressionStream("gzip"));
    buf = await new Response(stream).arrayBuffer();
  }

  function fillTrials() {
    const trials = [...new Set(D.episodes.map((e) => e.trial))];
    el.trial.innerHTML = trials.map((k) => `<option value="${k}">trial ${k}</option>`).join("");
    if (D.start_trial !== null && trials.includes(D.start_trial)) el.trial.value = D.start_trial;
  }
  function fillEpisodes() {
    const k = Number(el.trial.value);
    const eps = D.episodes.map((e, j) => [e, j]).filter(([e]) => e.trial === k);
    el.episode.innerHTML = eps.map(([e, j]) => `<option value="${j}">${
      `${e.kind} in ${e.world}`}</option>`).join("");
  }

  function select(j) {
    ep = D.episodes[j];
    A = {};
    for (const key of ["xy", "th", "reading", "memberships", "heading", "speed", "collision",
                       "contact", "reward", "rules", "goal"]) if (ep[key]) A[key] = view(ep[key]);
    A.collIdx = [];
    for (let r = 0; r < ep.n; r++) if (A.collision.v[r]) A.collIdx.push(r);
    el.slider.max = ep.n - 1;
    i = 0; el.slider.value = 0;
    buildBars();
    layout();
    draw();
  }

  function buildBars() {
    const c = A.memberships.w;
    el.bars.innerHTML = "";
    for (let s = 0; s < c; s++) {
      const row = document.createElement("div");
      row.className = "bar";
      row.innerHTML = `<span class="lab" title="${D.labels[s] || "S" + (s + 1)}">${D.labels[s] || "S" + (s + 1)}` +
        `</span><span class="track"><span class="fill" style="display:block"></span></span>` +
        `<span class="act"></span>`;
      el.bars.appendChild(row);
    }
  }

  let scale = 1, ox = 0, oy = 0;
  function layout() {
    const w = D.worlds[ep.world];
    const [x0, y0, x1, y1] = w ? w.bounds : [-5, -5, 5, 5];
    const pad = 0.3, aspect = (y1 - y0 + 2 * pad) / (x1 - x0 + 2 * pad);
    const maxH = Math.max(280, window.innerHeight * 0.8); // a tall world fits the window
    const cssW = Math.round(Math.min(el.canvas.parentElement.clientWidth || 600, maxH / aspect));
    const cssH = Math.round(cssW * aspect);
    const dpr = window.devicePixelRatio || 1;
    el.canvas.style.width = cssW + "px";
    el.canvas.style.height = cssH + "px";
    el.canvas.width = Math.round(cssW * dpr);
    el.canvas.height = Math.round(cssH * dpr);
    scale = (cssW * dpr) / (x1 - x0 + 2 * pad);
    ox = x0 - pad; oy = y1 + pad;
  }
  const X = (x) => (x - ox) * scale;
  const Y = (y) => (oy - y) * scale;

  function poly(ctx, pts, close) {
    ctx.beginPath();
    pts.forEach(([x, y], q) => (q ? ctx.lineTo(X(x), Y(y)) : ctx.moveTo(X(x), Y(y))));
    if (close) ctx.closePath();
  }

  function draw() {
    const ctx = el.canvas.getContext("2d");
    const px = scale / 100; // one centimetre in canvas pixels
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.clearRect(0, 0, el.canvas.width, el.canvas.height);
    const w = D.worlds[ep.world];
    if (w) {
      ctx.fillStyle = "#bdbdbd"; ctx.strokeStyle = "#404040"; ctx.lineWidth = Math.max(1, px * 1.2);
      for (const o of w.obstacles) { poly(ctx, o, true); ctx.fill(); ctx.stroke(); }
      ctx.strokeStyle = "#1a1a1a"; ctx.lineWidth = Math.max(2, px * 3); ctx.lineCap = "round";
      for (const wl of w.walls) { poly(ctx, wl, false); ctx.stroke(); }
      // the goal of this iteration's episode (goal episodes), else the world's [goal]
      const g = A.goal ? [at(A.goal, i, 0), at(A.goal, i, 1), at(A.goal, i, 2)] : w.goal;
      if (g) {
        ctx.fillStyle = "rgba(230,159,0,.35)"; ctx.beginPath();
        ctx.arc(X(g[0]), Y(g[1]), g[2] * scale, 0, 2 * Math.PI); ctx.fill();
      }
    }
    // path so far
    const trail = el.trail.value === "all" ? ep.n : Number(el.trail.value);
    const lo = Math.max(0, i - trail);
    ctx.strokeStyle = "rgba(0,114,178,.75)"; ctx.lineWidth = Math.max(1, px * 0.8);
    ctx.beginPath();
    for (let r = lo; r <= i; r++) {
      const wx = at(A.xy, r, 0), wy = at(A.xy, r, 1);
      // a jump longer than any step (0.45 m at 0.3 m/s) is a reset between episodes: no line
      const jump = r > lo && Math.hypot(wx - at(A.xy, r - 1, 0), wy - at(A.xy, r - 1, 1)) > 0.6;
      r === lo || jump ? ctx.moveTo(X(wx), Y(wy)) : ctx.lineTo(X(wx), Y(wy));
    }
    ctx.stroke();
    // collisions so far (crosses at the contact point)
    ctx.strokeStyle = "#d55e00"; ctx.lineWidth = Math.max(1.5, px * 1.5);
    const d = Math.max(4, px * 6);
    let shown = 0;
    for (let q = 0; q < A.collIdx.length && A.collIdx[q] <= i; q++) {
      const cx = X(at(A.contact, q, 0)), cy = Y(at(A.contact, q, 1));
      ctx.beginPath(); ctx.moveTo(cx - d, cy - d); ctx.lineTo(cx + d, cy + d);
      ctx.moveTo(cx - d, cy + d); ctx.lineTo(cx + d, cy - d); ctx.stroke();
      shown++;
    }
    // robot at the pose this iteration started from, and its beams
    const x = at(A.xy, i, 0), y = at(A.xy, i, 1), th = at(A.th, i);
    for (let b = 0; b < angles.length; b++) {
      const a = th + angles[b], r = at(A.reading, i, b);
      const free = r >= maxRange - 0.013;
      const rx = x + R * Math.cos(a), ry = y + R * Math.sin(a);
      const tx = rx + r * Math.cos(a), ty = ry + r * Math.sin(a);
      ctx.setLineDash(free ? [4, 4] : []);
      ctx.strokeStyle = free ? "#9a9a9a" : "#009e73"; ctx.lineWidth = Math.max(1, px * 0.9);
      ctx.beginPath(); ctx.moveTo(X(rx), Y(ry)); ctx.lineTo(X(tx), Y(ty)); ctx.stroke();
      if (!free) { ctx.fillStyle = "#009e73"; ctx.beginPath(); ctx.arc(X(tx), Y(ty), Math.max(2, px * 2), 0, 2 * Math.PI); ctx.fill(); }
    }
    ctx.setLineDash([]);
    const hit = A.collision.v[i] === 1;
    ctx.fillStyle = hit ? "#fde0cf" : "#fff"; ctx.strokeStyle = hit ? "#d55e00" : "#000";
    ctx.lineWidth = Math.max(1.5, px * 1.5);
    ctx.beginPath(); ctx.arc(X(x), Y(y), R * scale, 0, 2 * Math.PI); ctx.fill(); ctx.stroke();
    ctx.beginPath(); ctx.moveTo(X(x), Y(y));
    ctx.lineTo(X(x + R * Math.cos(th)), Y(y + R * Math.sin(th))); ctx.stroke();
    panel(shown, hit);
  }

  function fmtAct(v) {
    const u = ep.unit || "";
    return u === "deg" ? `${v > 0 ? "+" : ""}${v.toFixed(0)}°` : `${v.toFixed(2)} ${u}`.trim();
  }

  function panel(shown, hit) {
    const c = A.memberships.w;
    let dom = 0;
    for (let s = 1; s < c; s++) if (at(A.memberships, i, s) > at(A.memberships, i, dom)) dom = s;
    const rows = el.bars.children;
    const rr = A.rules ? (A.rules.v.length / c > 1 ? i : 0) : -1;
    for (let s = 0; s < c; s++) {
      rows[s].className = s === dom ? "bar dom" : "bar";
      rows[s].querySelector(".fill").style.width = (100 * at(A.memberships, i, s)).toFixed(1) + "%";
      rows[s].querySelector(".act").textContent = rr >= 0 ? fmtAct(ep.actions[A.rules.v[rr * c + s]]) : "";
    }
    let phase = ep.kind === "learning" ? "learning" : `frozen rule base (${ep.kind})`;
    if (ep.kind === "learning" && ep.convergence !== null)
      phase = i >= ep.convergence ? `frozen (converged at ${ep.convergence})` : `learning (converges at ${ep.convergence})`;
    const hd = at(A.heading, i), sp = at(A.speed, i);
    const rw = A.reward ? `${at(A.reward, i) >= 0 ? "+" : ""}${at(A.reward, i).toFixed(2)} (${ep.reward_label})` : "– (not logged)";
    el.iter.textContent = `${i} / ${ep.n - 1}`;
    el.info.innerHTML =
      `iteration  ${i}   t = ${(i * 1.5).toFixed(1)} s\n` +
      `phase      ${phase}\n` +
      `situation  ${D.labels[dom] || "S" + (dom + 1)} (u = ${at(A.memberships, i, dom).toFixed(2)})\n` +
      `command    turn ${hd >= 0 ? "+" : ""}${hd.toFixed(1)}°, ${sp.toFixed(2)} m/s\n` +
      `reward     ${rw}\n` +
      `collisions ${shown} so far of ${A.collIdx.length}` + (hit ? `   <span class="coll">COLLISION</span>` : "");
  }

  function setPlaying(p) {
    playing = p && i < ep.n - 1;
    el.play.textContent = playing ? "Pause" : "Play";
    root.dataset.playing = playing ? "1" : "0";
    if (playing) { last = performance.now(); acc = 0; requestAnimationFrame(tick); }
  }
  function tick(now) {
    if (!playing) return;
    acc += ((now - last) / 1000) * Number(el.speed.value);
    last = now;
    const step = Math.floor(acc);
    if (step > 0) {
      acc -= step;
      i = Math.min(ep.n - 1, i + step);
      el.slider.value = i;
      draw();
      if (i >= ep.n - 1) { setPlaying(false); return; }
    }
    requestAnimationFrame(tick);
  }

  el.trial.addEventListener("change", () => { setPlaying(false); fillEpisodes(); select(Number(el.episode.value)); });
  el.episode.addEventListener("change", () => { setPlaying(false); select(Number(el.episode.value)); });
  el.play.addEventListener("click", () => setPlaying(!playing));
  el.slider.addEventListener("input", () => { i = Number(el.slider.value); draw(); });
  el.trail.addEventListener("change", draw);
  window.addEventListener("resize", () => { if (ep) { layout(); draw(); } });
  root.addEventListener("keydown", (e) => {
    if (e.target.tagName === "SELECT") return;
    if (e.key === " ") { e.preventDefault(); setPlaying(!playing); }
    else if (e.key === "ArrowRight" || e.key === "ArrowLeft") {
      e.preventDefault(); setPlaying(false);
      i = Math.max(0, Math.min(ep.n - 1, i + (e.key === "ArrowRight" ? 1 : -1)));
      el.slider.value = i; draw();
    }
  });

  if (!D.episodes.length) { el.status.textContent = "This log has no replayable episode."; return; }
  if (typeof DecompressionStream === "undefined") {
    el.status.textContent = "The replay needs a browser with DecompressionStream " +
      "(Chrome/Edge 80+, Firefox 113+, Safari 16.4+).";
    return;
  }
  decode().then(() => {
    fillTrials(); fillEpisodes(); select(Number(el.episode.value));
    el.status.textContent = "";
    root.dataset.ready = "1";
  }).catch((err) => { el.status.textContent = "Cannot decode the replay data: " + err; });
})();
