// dbench result viewer: plain JavaScript, no network, works from file://.
// Reads window.DBENCH (data.js, written by dbench/report/html.py): images as little-endian
// half floats (base64), one entry per frame (sequences) or time bin (transient videos).
// Tone map as the report's LDR metrics: y = clip(x * 2^ev, 0, 1), then the sRGB curve.
(function () {
  "use strict";
  const D = window.DBENCH;
  if (!D) { document.body.textContent = "viewer/data.js is missing"; return; }
  // ---- tables -----------------------------------------------------------------------------
  function metricsTable(el, t) {
    const table = document.createElement("table"); table.className = "metrics";
    const head = table.createTHead().insertRow(), body = table.createTBody();
    t.columns.forEach((c, j) => {
      const th = document.createElement("th"); th.textContent = c; th.dataset.col = String(j);
      th.addEventListener("click", () => sortBy(j)); head.appendChild(th);
    });
    const rows = t.rows.map((r, i) => ({ r, i }));
    function render() {
      body.innerHTML = "";
      rows.forEach(({ r, i }) => {
        const tr = body.insertRow();
        if (t.flagged && t.flagged.includes(i)) tr.className = "worse";
        r.forEach((v, j) => {
          const td = tr.insertCell(); td.textContent = t.text ? t.text[i][j] : v;
          if (t.best && t.best[j] && t.best[j].includes(i)) td.className = "best";
        });
      });
    }
    let key = -1, dir = 1;
    function sortBy(j) {
      dir = key === j ? -dir : 1; key = j;
      rows.sort((a, b) => {
        const x = a.r[j], y = b.r[j];
        const nx = typeof x === "number", ny = typeof y === "number";
        if (nx && ny) return dir * (x - y);
        if (nx !== ny) return nx ? -1 : 1;
        return dir * String(x).localeCompare(String(y));
      });
      head.querySelectorAll("th").forEach((th, k) => {
        th.classList.toggle("sorted-asc", k === j && dir > 0);
        th.classList.toggle("sorted-desc", k === j && dir < 0);
      });
      render();
    }
    render();
    el.appendChild(table);
  }
  document.querySelectorAll("[data-table]").forEach(el => metricsTable(el, D.tables[+el.dataset.table]));

})();

(async function () {
  "use strict";
  const D = window.DBENCH;
  if (!D || !document.getElementById("main")) return;  // a page of tables only
  const W = D.width, H = D.height;

  // ---- half-float decoding ----------------------------------------------------------------
  // A frame is base64(zlib(low bytes of every half float, then their high bytes)): splitting
  // the bytes into two planes lets deflate find the smooth high bytes (about 40 % smaller).
  function halfToFloat(h) {
    const s = (h & 0x8000) ? -1 : 1, e = (h >> 10) & 0x1f, f = h & 0x3ff;
    if (e === 0) return s * Math.pow(2, -14) * (f / 1024);
    if (e === 31) return f ? NaN : s * Infinity;
    return s * Math.pow(2, e - 15) * (1 + f / 1024);
  }
  async function inflate(b64) {
    const bin = atob(b64), packed = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) packed[i] = bin.charCodeAt(i);
    const stream = new Blob([packed]).stream().pipeThrough(new DecompressionStream("deflate"));
    const bytes = new Uint8Array(await new Response(stream).arrayBuffer());
    const n = bytes.length >> 1, out = new Float32Array(n);
    for (let i = 0; i < n; i++) out[i] = halfToFloat(bytes[i] | (bytes[n + i] << 8));
    return out;
  }
  const decoded = await Promise.all(D.images.map(im => Promise.all(im.frames.map(inflate))));
  function linear(i, frame) {
    const frames = decoded[i];
    return frames[Math.min(frame, frames.length - 1)];
  }

  // ---- colour -----------------------------------------------------------------------------
  function srgb(c) { return c <= 0.0031308 ? 12.92 * c : 1.055 * Math.pow(c, 1 / 2.4) - 0.055; }
  function tonemap(x, ev) {
    const v = x * Math.pow(2, ev);
    return srgb(v > 1 ? 1 : (v > 0 ? v : 0));
  }
  // magma-like colour map (stops of matplotlib's magma), t in [0, 1]
  const MAGMA = [[0, 0, 4], [40, 11, 84], [101, 21, 110], [159, 42, 99], [212, 72, 66],
                 [245, 125, 21], [250, 193, 39], [252, 253, 191]];
  function magma(t) {
    t = Math.max(0, Math.min(1, t)) * (MAGMA.length - 1);
    const k = Math.min(MAGMA.length - 2, Math.floor(t)), u = t - k, a = MAGMA[k], b = MAGMA[k + 1];
    return [a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1]), a[2] + u * (b[2] - a[2])];
  }

  // ---- state ------------------------------------------------------------------------------
  const ref = D.images.findIndex(im => im.role === "reference");
  const state = {
    current: D.images.findIndex(im => im.role === "method") >= 0
      ? D.images.findIndex(im => im.role === "method") : 0,
    other: ref >= 0 ? ref : 0, mode: "image", ev: D.ev || 0, frame: D.start_frame || 0,
    split: false, splitAt: 0.5, scale: 1, cx: W / 2, cy: H / 2, playing: false,
  };

  // ---- layout -----------------------------------------------------------------------------
  const $ = id => document.getElementById(id);
  const main = $("main"), ctx = main.getContext("2d");
  const fit = Math.max(1, Math.floor(Math.min(720 / W, 540 / H)) || 1);
  const dispW = Math.max(W * fit, Math.min(720, W * 8)), dispH = Math.round(dispW * H / W);
  main.width = dispW; main.height = dispH;
  const baseScale = dispW / W;

  function rgbaOf(i, mode, ev, frame) {
    const x = linear(i, frame), out = new Uint8ClampedArray(W * H * 4);
    const r = ref >= 0 ? linear(ref, frame) : null;
    for (let p = 0, q = 0; p < W * H; p++, q += 3) {
      let c;
      if (mode === "image" || !r) {
        c = [255 * tonemap(x[q], ev), 255 * tonemap(x[q + 1], ev), 255 * tonemap(x[q + 2], ev)];
      } else if (mode === "relative") {
        let e = 0;
        for (let k = 0; k < 3; k++) e += Math.abs(x[q + k] - r[q + k]) / (Math.abs(r[q + k]) + 0.01);
        c = magma(e / 3);
      } else {
        let e = 0;
        for (let k = 0; k < 3; k++) e += Math.abs(x[q + k] - r[q + k]);
        c = magma(tonemap(e / 3, ev));
      }
      out[4 * p] = c[0]; out[4 * p + 1] = c[1]; out[4 * p + 2] = c[2]; out[4 * p + 3] = 255;
    }
    return out;
  }
  const layers = new Map();
  function layer(i) {
    const key = [i, state.mode, state.ev, state.frame].join("|");
    if (!layers.has(key)) {
      if (layers.size > 64) layers.clear();
      const c = document.createElement("canvas");
      c.width = W; c.height = H;
      c.getContext("2d").putImageData(new ImageData(rgbaOf(i, state.mode, state.ev, state.frame), W, H), 0, 0);
      layers.set(key, c);
    }
    return layers.get(key);
  }
  function drawView(target, i, w, h, clipFrom) {
    const g = target.getContext("2d"), s = state.scale * (w / W);
    g.imageSmoothingEnabled = false;
    g.save();
    if (clipFrom !== undefined) { g.beginPath(); g.rect(clipFrom, 0, w - clipFrom, h); g.clip(); }
    else { g.fillStyle = "#000"; g.fillRect(0, 0, w, h); }
    g.setTransform(s, 0, 0, s, w / 2 - state.cx * s, h / 2 - state.cy * s);
    g.drawImage(layer(i), 0, 0);
    g.restore();
  }
  function draw() {
    drawView(main, state.current, dispW, dispH);
    if (state.split) {
      const at = Math.round(state.splitAt * dispW);
      drawView(main, state.other, dispW, dispH, at);
      ctx.fillStyle = "#fff"; ctx.fillRect(at - 1, 0, 2, dispH);
    }
    document.querySelectorAll(".thumb").forEach((t, i) => {
      t.classList.toggle("active", i === state.current);
      const c = t.querySelector("canvas");
      drawView(c, i, c.width, c.height);
    });
    const img = D.images[state.current];
    $("status").textContent =
      `${img.label}` + (state.split ? ` | ${D.images[state.other].label}` : "") +
      `   mode ${state.mode}   exposure ${state.ev >= 0 ? "+" : ""}${state.ev} EV   zoom ${state.scale.toFixed(2)}x` +
      (D.frame_labels ? `   ${D.frame_labels[state.frame]}` : "");
    $("exposure-value").textContent = `${state.ev} EV`;
    if (D.frame_labels) {
      $("frame").value = state.frame; $("frame-label").textContent = D.frame_labels[state.frame];
    }
    document.body.dataset.current = String(state.current);
    document.body.dataset.frame = String(state.frame);
  }

  // ---- controls ---------------------------------------------------------------------------
  function select(i) { if (i >= 0 && i < D.images.length) { state.current = i; draw(); } }
  function setExposure(ev) { state.ev = Math.round(ev * 2) / 2; $("exposure").value = state.ev; draw(); }
  function setFrame(f) {
    const n = D.frame_labels ? D.frame_labels.length : 1;
    state.frame = ((f % n) + n) % n; draw();
  }
  function zoomTo(x0, y0, side) {
    state.cx = x0 + side / 2; state.cy = y0 + side / 2;
    state.scale = Math.max(1, Math.min(W / side, H / side)); draw();
  }
  function resetView() { state.cx = W / 2; state.cy = H / 2; state.scale = 1; draw(); }

  const thumbs = $("thumbs");
  D.images.forEach((im, i) => {
    const t = document.createElement("div");
    t.className = "thumb"; t.dataset.index = String(i);
    const c = document.createElement("canvas");
    c.width = Math.max(96, Math.min(160, W)); c.height = Math.round(c.width * H / W);
    t.appendChild(c);
    const l = document.createElement("div");
    l.textContent = `${i + 1 <= 9 ? i + 1 + ": " : ""}${im.label}`;
    t.appendChild(l);
    t.addEventListener("click", () => select(i));
    thumbs.appendChild(t);
  });
  const other = $("other");
  D.images.forEach((im, i) => {
    const o = document.createElement("option"); o.value = String(i); o.textContent = im.label;
    other.appendChild(o);
  });
  other.value = String(state.other);
  other.addEventListener("change", () => { state.other = +other.value; draw(); });
  $("split").addEventListener("change", e => { state.split = e.target.checked; draw(); });
  $("exposure").value = state.ev;
  $("exposure").addEventListener("input", e => setExposure(+e.target.value));
  document.querySelectorAll("input[name=mode]").forEach(r => r.addEventListener("change", e => {
    state.mode = e.target.value; draw();
  }));
  $("reset").addEventListener("click", resetView);
  $("zoomwin").addEventListener("click", () => zoomTo(D.zoom.x0, D.zoom.y0, D.zoom.side));

  let drag = null;
  main.addEventListener("mousedown", e => {
    if (state.split && e.shiftKey) return;
    drag = { x: e.clientX, y: e.clientY, cx: state.cx, cy: state.cy };
    main.classList.add("dragging");
  });
  window.addEventListener("mouseup", () => { drag = null; main.classList.remove("dragging"); });
  main.addEventListener("mousemove", e => {
    const rect = main.getBoundingClientRect();
    if (state.split && (e.shiftKey || e.buttons === 0)) {
      if (e.shiftKey) { state.splitAt = (e.clientX - rect.left) / rect.width; draw(); }
    }
    if (!drag) return;
    const s = state.scale * baseScale;
    state.cx = drag.cx - (e.clientX - drag.x) / s; state.cy = drag.cy - (e.clientY - drag.y) / s;
    draw();
  });
  main.addEventListener("wheel", e => {
    e.preventDefault();
    const rect = main.getBoundingClientRect(), s = state.scale * baseScale;
    const px = state.cx + (e.clientX - rect.left - dispW / 2) / s;
    const py = state.cy + (e.clientY - rect.top - dispH / 2) / s;
    const k = e.deltaY < 0 ? 1.25 : 0.8;
    state.scale = Math.max(0.25, Math.min(64, state.scale * k));
    const s2 = state.scale * baseScale;
    state.cx = px - (e.clientX - rect.left - dispW / 2) / s2;
    state.cy = py - (e.clientY - rect.top - dispH / 2) / s2;
    draw();
  }, { passive: false });
  $("split-at").addEventListener("input", e => { state.splitAt = +e.target.value; draw(); });

  let timer = null;
  function play(on) {
    state.playing = on;
    if ($("play")) $("play").textContent = on ? "pause" : "play";
    if (timer) { clearInterval(timer); timer = null; }
    if (on) timer = setInterval(() => setFrame(state.frame + 1), 1000 / (D.fps || 8));
  }
  if (D.frame_labels) {
    $("player").hidden = false;
    $("frame").max = String(D.frame_labels.length - 1);
    $("frame").addEventListener("input", e => setFrame(+e.target.value));
    $("play").addEventListener("click", () => play(!state.playing));
  }
  window.addEventListener("keydown", e => {
    if (e.target.tagName === "INPUT" && e.target.type !== "range" && e.target.type !== "radio" &&
        e.target.type !== "checkbox") return;
    if (e.key >= "1" && e.key <= "9") select(+e.key - 1);
    else if (e.key === "ArrowRight") select((state.current + 1) % D.images.length);
    else if (e.key === "ArrowLeft") select((state.current - 1 + D.images.length) % D.images.length);
    else if (e.key === "+" || e.key === "=") setExposure(state.ev + 0.5);
    else if (e.key === "-") setExposure(state.ev - 0.5);
    else if (e.key === "0") resetView();
    else if (e.key === "z") zoomTo(D.zoom.x0, D.zoom.y0, D.zoom.side);
    else if (e.key === " " && D.frame_labels) { e.preventDefault(); play(!state.playing); }
    else if (e.key === "," && D.frame_labels) setFrame(state.frame - 1);
    else if (e.key === "." && D.frame_labels) setFrame(state.frame + 1);
    else return;
    e.preventDefault();
  });

  window.dbenchViewer = { state, select, setExposure, setFrame, zoomTo, draw, linear };
  if (D.zoom) zoomTo(D.zoom.x0, D.zoom.y0, D.zoom.side); else draw();
  document.body.dataset.ready = "1";
})();
