// A small hand-written WebGL viewer: the height map as a lit, height-coloured mesh and the
// toolpath as a polyline. About 250 lines instead of a vendored 600 kB library; it needs
// nothing from the internet. Drag turns, wheel or pinch zooms, "Reset view" goes back.
// A map with an uncertainty_mm column can be coloured by it instead of by height (a toggle):
// green is sure, red is over 3 x the low-confidence threshold (0.1 mm).
"use strict";
(function () {
  const canvas = document.getElementById("view3d");
  if (!canvas) return;
  const info = document.getElementById("view-info");
  const gl = canvas.getContext("webgl", { antialias: true, preserveDrawingBuffer: true });
  if (!gl) { info.textContent = "This browser has no WebGL; download the STL instead."; return; }

  // ---- tiny matrix helpers (column-major, as WebGL wants)
  function mul(a, b) { const o = new Float32Array(16); for (let i = 0; i < 4; i++) for (let j = 0; j < 4; j++) { let s = 0; for (let k = 0; k < 4; k++) s += a[k * 4 + j] * b[i * 4 + k]; o[i * 4 + j] = s; } return o; }
  function persp(fovy, asp, n, f) { const t = 1 / Math.tan(fovy / 2); return new Float32Array([t / asp, 0, 0, 0, 0, t, 0, 0, 0, 0, (f + n) / (n - f), -1, 0, 0, 2 * f * n / (n - f), 0]); }
  function rotX(a) { const c = Math.cos(a), s = Math.sin(a); return new Float32Array([1, 0, 0, 0, 0, c, s, 0, 0, -s, c, 0, 0, 0, 0, 1]); }
  function rotZ(a) { const c = Math.cos(a), s = Math.sin(a); return new Float32Array([c, s, 0, 0, -s, c, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]); }
  function trans(x, y, z) { return new Float32Array([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, x, y, z, 1]); }

  const VS = `attribute vec3 p; attribute vec3 n; attribute vec3 c; uniform mat4 mvp; uniform mat4 rot; varying vec3 vc; varying float li;
    void main(){ gl_Position = mvp * vec4(p,1.0); vec3 nn = normalize((rot * vec4(n,0.0)).xyz); li = 0.35 + 0.65 * abs(dot(nn, normalize(vec3(0.3,0.5,1.0)))); vc = c; }`;
  const FS = `precision mediump float; varying vec3 vc; varying float li; uniform float lit; void main(){ gl_FragColor = vec4(lit > 0.5 ? vc * li : vc, 1.0); }`;
  function shader(type, src) { const s = gl.createShader(type); gl.shaderSource(s, src); gl.compileShader(s); if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s)); return s; }
  const prog = gl.createProgram();
  gl.attachShader(prog, shader(gl.VERTEX_SHADER, VS)); gl.attachShader(prog, shader(gl.FRAGMENT_SHADER, FS)); gl.linkProgram(prog);
  const loc = { p: gl.getAttribLocation(prog, "p"), n: gl.getAttribLocation(prog, "n"), c: gl.getAttribLocation(prog, "c"),
                mvp: gl.getUniformLocation(prog, "mvp"), rot: gl.getUniformLocation(prog, "rot"), lit: gl.getUniformLocation(prog, "lit") };

  function buffer(data) { const b = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, b); gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW); return b; }
  function colour(t) { // blue (low) -> cyan -> yellow (high)
    return [Math.min(1, Math.max(0, 2 * t - 0.6)), 0.35 + 0.6 * t, Math.max(0.15, 1 - 1.1 * t)];
  }

  const UNCERTAIN_MM = 0.1;
  function uncertaintyColour(u) { // green (sure) -> yellow (at the threshold) -> red (3 x over it)
    if (!isFinite(u)) return [0.55, 0.55, 0.55];
    const t = Math.min(1, Math.max(0, u / (3 * UNCERTAIN_MM)));
    return t < 1 / 3 ? [0.2 + 2.4 * t, 0.75, 0.25] : [1, Math.max(0.15, 0.75 - 0.9 * (t - 1 / 3)), 0.2];
  }

  let mesh = null, path = null, centre = [0, 0, 0], size = 50, heightmap = null;
  const view = { yaw: -0.6, pitch: 0.95, dist: 2.1 };
  const home = Object.assign({}, view);

  function parseHeightmap(text) {
    // x,y,z first; further columns by their header names (old files have none)
    const lines = text.trim().split(/\r?\n/);
    const head = (lines[0] || "").split(",").map((c) => c.trim().toLowerCase());
    const ui = head.indexOf("uncertainty_mm");
    const rows = lines.slice(1).map((l) => l.split(",")).filter((c) => c.length === head.length)
      .map((c) => [Number(c[0]), Number(c[1]), Number(c[2]), ui >= 0 && c[ui] !== "" ? Number(c[ui]) : NaN])
      .filter((r) => r.slice(0, 3).every(isFinite));
    const xs = [...new Set(rows.map((r) => r[0].toFixed(4)))].map(Number).sort((a, b) => a - b);
    const ys = [...new Set(rows.map((r) => r[1].toFixed(4)))].map(Number).sort((a, b) => a - b);
    const dx = xs.length > 1 ? Math.min(...xs.slice(1).map((v, i) => v - xs[i])) : 1;
    const dy = ys.length > 1 ? Math.min(...ys.slice(1).map((v, i) => v - ys[i])) : 1;
    const nx = Math.round((xs[xs.length - 1] - xs[0]) / dx) + 1, ny = Math.round((ys[ys.length - 1] - ys[0]) / dy) + 1;
    const z = new Float32Array(nx * ny).fill(NaN), u = new Float32Array(nx * ny).fill(NaN);
    rows.forEach((r) => { const k = Math.round((r[1] - ys[0]) / dy) * nx + Math.round((r[0] - xs[0]) / dx); z[k] = r[2]; u[k] = r[3]; });
    return { x0: xs[0], y0: ys[0], dx, dy, nx, ny, z, u, n: rows.length, hasU: ui >= 0 };
  }
  function buildMesh(h, byUncertainty) {
    let lo = Infinity, hi = -Infinity; h.z.forEach((v) => { if (!isNaN(v)) { lo = Math.min(lo, v); hi = Math.max(hi, v); } });
    const P = [], N = [], C = [];
    const at = (i, j) => h.z[j * h.nx + i];
    const vtx = (i, j) => [h.x0 + i * h.dx, h.y0 + j * h.dy, at(i, j), h.u[j * h.nx + i]];
    for (let j = 0; j + 1 < h.ny; j++) for (let i = 0; i + 1 < h.nx; i++) {
      const q = [[i, j], [i + 1, j], [i, j + 1], [i + 1, j + 1]];
      for (const tri of [[0, 1, 2], [1, 3, 2]]) {
        const v = tri.map((k) => vtx(q[k][0], q[k][1]));
        if (v.some((p) => isNaN(p[2]))) continue;
        const a = [v[1][0] - v[0][0], v[1][1] - v[0][1], v[1][2] - v[0][2]], b = [v[2][0] - v[0][0], v[2][1] - v[0][1], v[2][2] - v[0][2]];
        const nrm = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
        v.forEach((p) => { P.push(p[0], p[1], p[2]); N.push(...nrm);
          C.push(...(byUncertainty ? uncertaintyColour(p[3]) : colour(hi > lo ? (p[2] - lo) / (hi - lo) : 0.5))); });
      }
    }
    centre = [h.x0 + (h.nx - 1) * h.dx / 2, h.y0 + (h.ny - 1) * h.dy / 2, (lo + hi) / 2];
    size = Math.max((h.nx - 1) * h.dx, (h.ny - 1) * h.dy, hi - lo, 1);
    return { count: P.length / 3, p: buffer(new Float32Array(P)), n: buffer(new Float32Array(N)), c: buffer(new Float32Array(C)), lo, hi };
  }
  const RAPID = [0.35, 0.8, 1], CUT = [1, 0.42, 0.15];      // the legend under the view names them
  function parseGcode(text) {
    const P = [], C = []; let x = 0, y = 0, z = 0, moves = 0, rapids = 0, mode = "1";
    text.split(/\r?\n/).forEach((line) => {
      line = line.replace(/\(.*?\)|;.*$/g, "").toUpperCase();
      const g = line.match(/G0*([0-3])(?!\d)/);
      if (g) mode = g[1];                                    // motion is modal: it holds until the next G0-G3
      if (!/[XYZ]/.test(line)) return;
      const get = (k, d) => { const m = line.match(new RegExp(k + "\\s*(-?[0-9.]+)")); return m ? parseFloat(m[1]) : d; };
      const nx = get("X", x), ny = get("Y", y), nz = get("Z", z);
      if (moves > 0) {                                       // arcs are drawn as chords to their end point
        P.push(x, y, z, nx, ny, nz);
        const c = mode === "0" ? RAPID : CUT;
        C.push(...c, ...c);
        if (mode === "0") rapids++;
      }
      x = nx; y = ny; z = nz; moves++;
    });
    const n = P.length / 3;
    return { count: n, p: buffer(new Float32Array(P)), n: buffer(new Float32Array(n * 3).fill(1)), c: buffer(new Float32Array(C)),
             moves, rapids, segments: n / 2 };
  }

  function bind(obj) {
    [["p", obj.p], ["n", obj.n], ["c", obj.c]].forEach(([k, b]) => { gl.bindBuffer(gl.ARRAY_BUFFER, b); gl.enableVertexAttribArray(loc[k]); gl.vertexAttribPointer(loc[k], 3, gl.FLOAT, false, 0, 0); });
  }
  function draw() {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.round(canvas.clientWidth * dpr), h = Math.round(canvas.clientHeight * dpr);
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    gl.viewport(0, 0, w, h); gl.clearColor(0.063, 0.094, 0.125, 1); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST); gl.useProgram(prog);
    const rot = mul(rotX(-view.pitch), rotZ(view.yaw));
    const model = mul(rot, trans(-centre[0], -centre[1], -centre[2]));
    const mvp = mul(persp(0.8, w / Math.max(1, h), size * 0.05, size * 20), mul(trans(0, 0, -view.dist * size), model));
    gl.uniformMatrix4fv(loc.mvp, false, mvp); gl.uniformMatrix4fv(loc.rot, false, rot);
    // the surface is pushed back a little in depth so that a toolpath lying on it stays visible
    gl.enable(gl.POLYGON_OFFSET_FILL); gl.polygonOffset(2, 2);
    if (mesh && document.getElementById("show-surface").checked) { gl.uniform1f(loc.lit, 1); bind(mesh); gl.drawArrays(gl.TRIANGLES, 0, mesh.count); }
    gl.disable(gl.POLYGON_OFFSET_FILL);
    if (path && document.getElementById("show-path").checked) {
      gl.uniform1f(loc.lit, 0); bind(path); gl.drawArrays(gl.LINES, 0, 2 * Math.min(path.segments, shownSegments()));
    }
  }
  // ---- program playback: the toolpath drawn up to a move, by hand (the slider) or played
  const play = document.getElementById("playback"), playBtn = document.getElementById("play");
  function shownSegments() { return play && path ? Math.round(path.segments * Number(play.value) / 1000) : Infinity; }
  let playing = null;
  function stopPlaying() { if (playing) { cancelAnimationFrame(playing); playing = null; } if (playBtn) playBtn.textContent = "Play the program"; }
  if (play) {
    play.addEventListener("input", () => { stopPlaying(); redraw(); });
    playBtn.addEventListener("click", () => {
      if (playing) { stopPlaying(); return; }
      if (Number(play.value) >= 1000) play.value = 0;
      playBtn.textContent = "Pause";
      const t0 = performance.now(), v0 = Number(play.value);
      const step = (t) => {                                  // the whole program in about 20 s
        play.value = Math.min(1000, v0 + (t - t0) / 20);
        draw();
        if (Number(play.value) < 1000) playing = requestAnimationFrame(step); else stopPlaying();
      };
      playing = requestAnimationFrame(step);
    });
  }
  let queued = false;
  function redraw() { if (!queued) { queued = true; requestAnimationFrame(() => { queued = false; draw(); }); } }

  // ---- orbit and zoom with mouse, touch and pen (pointer events), pinch with two fingers
  const pts = new Map(); let pinch0 = null;
  canvas.addEventListener("pointerdown", (e) => { canvas.setPointerCapture(e.pointerId); pts.set(e.pointerId, [e.clientX, e.clientY]); });
  canvas.addEventListener("pointerup", (e) => { pts.delete(e.pointerId); pinch0 = null; });
  canvas.addEventListener("pointercancel", (e) => { pts.delete(e.pointerId); pinch0 = null; });
  canvas.addEventListener("pointermove", (e) => {
    if (!pts.has(e.pointerId)) return;
    const prev = pts.get(e.pointerId); pts.set(e.pointerId, [e.clientX, e.clientY]);
    if (pts.size === 2) {
      const [a, b] = [...pts.values()]; const d = Math.hypot(a[0] - b[0], a[1] - b[1]);
      if (pinch0) view.dist = Math.min(8, Math.max(0.3, view.dist * pinch0 / d)); pinch0 = d;
    } else {
      view.yaw += (e.clientX - prev[0]) * 0.01;
      view.pitch = Math.min(1.55, Math.max(0, view.pitch - (e.clientY - prev[1]) * 0.01));
    }
    redraw();
  });
  canvas.addEventListener("wheel", (e) => { e.preventDefault(); view.dist = Math.min(8, Math.max(0.3, view.dist * Math.exp(e.deltaY * 0.001))); redraw(); }, { passive: false });
  document.getElementById("reset-view").addEventListener("click", () => { Object.assign(view, home); redraw(); });
  ["show-path", "show-surface"].forEach((id) => document.getElementById(id).addEventListener("change", redraw));
  const byU = document.getElementById("colour-uncertainty");
  if (byU) byU.addEventListener("change", () => { if (heightmap) { mesh = buildMesh(heightmap, byU.checked); redraw(); } });
  window.addEventListener("resize", redraw);

  const get = (u) => fetch(u, { credentials: "same-origin" }).then((r) => { if (!r.ok) throw new Error(u + ": " + r.status); return r.text(); });
  (async () => {
    try {
      const hm = heightmap = parseHeightmap(await get(canvas.dataset.heightmap));
      if (byU) { byU.disabled = !hm.hasU; byU.parentElement.title = hm.hasU ? "" : "this height map carries no uncertainty"; }
      mesh = buildMesh(hm, byU && byU.checked && hm.hasU);
      let msg = hm.n + " height-map points, z " + mesh.lo.toFixed(2) + " to " + mesh.hi.toFixed(2) + " mm";
      if (canvas.dataset.gcode) {
        path = parseGcode(await get(canvas.dataset.gcode));
        msg += ", " + path.moves + " toolpath moves (" + path.rapids + " rapid)";
        canvas.dataset.rapids = path.rapids; canvas.dataset.cuts = path.segments - path.rapids;
      }
      info.textContent = msg + ". Drag to turn, pinch or wheel to zoom.";
      canvas.dataset.ready = "1";
      redraw();
    } catch (e) { info.textContent = "3D view failed: " + e.message; canvas.dataset.ready = "error"; }
  })();
})();
