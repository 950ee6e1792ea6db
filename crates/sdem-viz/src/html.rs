//! A self-contained 3D viewer page: inline JavaScript and WebGL, the points embedded as base64
//! `Float32Array`s, no network. Falls back to a 2D canvas projection where WebGL is missing.

use super::draw::quantile;
use super::map_view::MapView;

/// At most this many map points go into the page (more are thinned evenly).
pub const VIEWER_MAX_POINTS: usize = 300_000;

/// Standard base64 (RFC 4648, with padding).
pub(crate) fn base64(bytes: &[u8]) -> String {
    use base64::Engine;
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

/// Little-endian `f32` triples, base64.
fn encode_xyz(points: impl Iterator<Item = [f32; 3]>) -> String {
    let mut bytes = Vec::new();
    for p in points {
        for v in p {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    base64(&bytes)
}

/// Text safe inside HTML.
fn escape_html(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A JSON value safe inside a `<script>` element.
fn script_json(value: &serde_json::Value) -> String {
    value.to_string().replace("</", "<\\/")
}

/// A self-contained HTML page showing the map in 3D: points coloured by height (viridis, a colour
/// bar in metres), the trajectory (red), the nodes (numbered), the loop closures (magenta).
/// Mouse: drag to orbit, wheel to zoom, shift-drag or right-drag to pan; key `c` shows or hides
/// the points above the ceiling cut ([`MapView::plan_ceiling_cut`], hidden at first), `r`
/// resets the view.
///
/// The page loads nothing: the script is inline and the points are embedded as base64
/// little-endian `f32` arrays (at most [`VIEWER_MAX_POINTS`], thinned evenly), relative to the
/// map's centre. Without WebGL it draws the same view on a 2D canvas.
///
/// # Arguments
/// * `view` — the points, node poses and loop closures.
/// * `title` — the page's title.
///
/// # Example
/// ```
/// use sdem::geometry::{Pose, Vec3};
/// use sdem_viz::{viewer_html, MapView};
/// let points = vec![Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.5)];
/// let poses = vec![Pose::identity()];
/// let view = MapView { points_in_world: &points, world_from_node: &poses, loop_closures: &[] };
/// let page = viewer_html(&view, "two points");
/// assert!(page.starts_with("<!DOCTYPE html>") && !page.contains("https://"));
/// ```
pub fn viewer_html(view: &MapView, title: &str) -> String {
    viewer_html_with_status(view, title, &[])
}

/// [`viewer_html`] with how the loop took each node: `status[i]` is node `i`'s status word
/// (`tracked`, `recovered`, `relocalized`, `new_segment`, `doubtful`, or `first`; missing or
/// empty: none). Every node not simply tracked is labelled with its status, in its own colour,
/// whatever the zoom, and the page counts the nodes by status.
///
/// # Example
/// ```
/// use sdem::geometry::{Pose, Vec3};
/// use sdem_viz::{viewer_html_with_status, MapView};
/// let points = vec![Vec3::new(1.0, 0.0, 0.0)];
/// let poses = vec![Pose::identity(), Pose::translation(0.5, 0.0, 0.0)];
/// let view = MapView { points_in_world: &points, world_from_node: &poses, loop_closures: &[] };
/// let page = viewer_html_with_status(&view, "two stops", &["first", "new_segment"]);
/// assert!(page.contains("new_segment"));
/// ```
pub fn viewer_html_with_status(view: &MapView, title: &str, status: &[&str]) -> String {
    let finite: Vec<&sdem::geometry::Vec3> = view
        .points_in_world
        .iter()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .collect();
    let stride = finite.len().div_ceil(VIEWER_MAX_POINTS).max(1);
    let shown: Vec<&sdem::geometry::Vec3> = finite.iter().step_by(stride).copied().collect();
    let nodes = view.node_positions();
    // Centre: the middle of the points' robust bounds (or of the nodes).
    let mut center = [0.0f64; 3];
    for (k, c) in center.iter_mut().enumerate() {
        let mut v: Vec<f64> = shown.iter().map(|p| p[k]).collect();
        if v.is_empty() {
            v = nodes.iter().map(|p| p[k]).collect();
        }
        let lo = quantile(&mut v, 0.02).unwrap_or(0.0);
        let hi = quantile(&mut v, 0.98).unwrap_or(0.0);
        *c = 0.5 * (lo + hi);
    }
    let mut zs: Vec<f64> = shown.iter().map(|p| p.z).collect();
    let z_lo = quantile(&mut zs, 0.01).unwrap_or(0.0);
    let z_hi = quantile(&mut zs, 0.99).unwrap_or(1.0).max(z_lo + 0.1);
    let mut radius_samples: Vec<f64> = shown
        .iter()
        .map(|p| ((p.x - center[0]).powi(2) + (p.y - center[1]).powi(2)).sqrt())
        .collect();
    radius_samples.extend(
        nodes
            .iter()
            .map(|p| ((p.x - center[0]).powi(2) + (p.y - center[1]).powi(2)).sqrt()),
    );
    let extent = quantile(&mut radius_samples, 0.98).unwrap_or(5.0).max(1.0);
    let relative = |p: &sdem::geometry::Vec3| {
        [
            (p.x - center[0]) as f32,
            (p.y - center[1]) as f32,
            (p.z - center[2]) as f32,
        ]
    };
    let loops: Vec<[usize; 2]> = view
        .loop_closures
        .iter()
        .filter(|(a, b)| *a < nodes.len() && *b < nodes.len())
        .map(|&(a, b)| [a, b])
        .collect();
    let data = serde_json::json!({
        "title": title,
        "points": encode_xyz(shown.iter().map(|p| relative(p))),
        "nodes": encode_xyz(nodes.iter().map(relative)),
        "loops": loops,
        "center": center,
        "zLo": z_lo - center[2],
        "zHi": z_hi - center[2],
        "zCut": view.plan_ceiling_cut().map(|z| z - center[2]).unwrap_or(1e9),
        "extent": extent,
        "status": status,
        "pointCount": view.points_in_world.len(),
        "shownCount": shown.len(),
    });
    PAGE.replace("@TITLE@", &escape_html(title))
        .replace("@DATA@", &script_json(&data))
}

/// The page; `@TITLE@` and `@DATA@` are filled in.
const PAGE: &str = r##"<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>@TITLE@ - sdem map viewer</title>
<style>
  html, body { margin: 0; height: 100%; background: #ffffff; overflow: hidden; font: 14px sans-serif; }
  canvas { position: absolute; left: 0; top: 0; width: 100%; height: 100%; }
  #overlay { pointer-events: none; }
</style>
</head>
<body>
<canvas id="gl"></canvas>
<canvas id="overlay"></canvas>
<script>
"use strict";
(function () {
  const DATA = @DATA@;
  function decode(text) {
    const raw = atob(text);
    const bytes = new Uint8Array(raw.length);
    for (let i = 0; i < raw.length; i++) bytes[i] = raw.charCodeAt(i);
    return new Float32Array(bytes.buffer);
  }
  const points = decode(DATA.points);
  const nodes = decode(DATA.nodes);
  const glCanvas = document.getElementById("gl");
  const overlay = document.getElementById("overlay");
  const ctx2d = overlay.getContext("2d");
  const view = { yaw: -2.2, pitch: 0.75, distance: 2.6 * DATA.extent, target: [0, 0, 0], showCeiling: false };
  const home = JSON.parse(JSON.stringify(view));

  // Viridis, the polynomial fit; the same in the shader.
  const VIRIDIS = [
    [0.2777273272234177, 0.005407344544966578, 0.3340998053353061],
    [0.1050930431085774, 1.404613529898575, 1.384590162594685],
    [-0.3308618287255563, 0.214847559468213, 0.09509516302823659],
    [-4.634230498983486, -5.799100973351585, -19.33244095627987],
    [6.228269936347081, 14.17993336680509, 56.69055260068105],
    [4.776384997670288, -13.74514537774601, -65.35303263337234],
    [-5.435455855934631, 4.645852612178535, 26.3124352495832]
  ];
  function viridis(t) {
    t = Math.min(1, Math.max(0, t));
    const out = [0, 0, 0];
    for (let k = 0; k < 3; k++) {
      let v = VIRIDIS[6][k];
      for (let i = 5; i >= 0; i--) v = VIRIDIS[i][k] + t * v;
      out[k] = Math.round(255 * Math.min(1, Math.max(0, v)));
    }
    return out;
  }

  // Column-major 4x4 matrices.
  function multiply(a, b) {
    const o = new Float32Array(16);
    for (let c = 0; c < 4; c++)
      for (let r = 0; r < 4; r++) {
        let s = 0;
        for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
        o[c * 4 + r] = s;
      }
    return o;
  }
  function perspective(fovy, aspect, near, far) {
    const f = 1 / Math.tan(fovy / 2);
    const o = new Float32Array(16);
    o[0] = f / aspect; o[5] = f; o[10] = (far + near) / (near - far); o[11] = -1;
    o[14] = 2 * far * near / (near - far);
    return o;
  }
  function lookAt(eye, target, up) {
    const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    const norm = (a) => { const l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; };
    const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    const z = norm(sub(eye, target));
    const x = norm(cross(up, z));
    const y = cross(z, x);
    return new Float32Array([x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
      -dot(x, eye), -dot(y, eye), -dot(z, eye), 1]);
  }
  function eye() {
    const c = Math.cos(view.pitch);
    return [view.target[0] + view.distance * c * Math.cos(view.yaw),
            view.target[1] + view.distance * c * Math.sin(view.yaw),
            view.target[2] + view.distance * Math.sin(view.pitch)];
  }
  function matrix(width, height) {
    const near = Math.max(0.01, view.distance / 1000);
    const far = view.distance * 10 + 4 * DATA.extent;
    return multiply(perspective(Math.PI / 4, width / height, near, far), lookAt(eye(), view.target, [0, 0, 1]));
  }
  function project(m, x, y, z, width, height) {
    const cx = m[0] * x + m[4] * y + m[8] * z + m[12];
    const cy = m[1] * x + m[5] * y + m[9] * z + m[13];
    const cw = m[3] * x + m[7] * y + m[11] * z + m[15];
    if (cw <= 1e-6) return null;
    return [(cx / cw * 0.5 + 0.5) * width, (0.5 - cy / cw * 0.5) * height, cw];
  }

  // WebGL, when there is one.
  let gl = null;
  try {
    gl = glCanvas.getContext("webgl", { preserveDrawingBuffer: true, antialias: true }) ||
         glCanvas.getContext("experimental-webgl", { preserveDrawingBuffer: true });
  } catch (e) { gl = null; }
  let program = null, pointBuffer = null, nodeBuffer = null, loopBuffer = null, loopCount = 0;
  let trailBuffer = null, trailCount = 0;
  if (gl) {
    const vs = `
      attribute vec3 position;
      uniform mat4 matrix;
      uniform float pointSize, zLo, zHi, zCut, byHeight;
      uniform vec3 color;
      varying vec3 vColor;
      vec3 viridis(float t) {
        const vec3 c0 = vec3(0.2777273272234177, 0.005407344544966578, 0.3340998053353061);
        const vec3 c1 = vec3(0.1050930431085774, 1.404613529898575, 1.384590162594685);
        const vec3 c2 = vec3(-0.3308618287255563, 0.214847559468213, 0.09509516302823659);
        const vec3 c3 = vec3(-4.634230498983486, -5.799100973351585, -19.33244095627987);
        const vec3 c4 = vec3(6.228269936347081, 14.17993336680509, 56.69055260068105);
        const vec3 c5 = vec3(4.776384997670288, -13.74514537774601, -65.35303263337234);
        const vec3 c6 = vec3(-5.435455855934631, 4.645852612178535, 26.3124352495832);
        t = clamp(t, 0.0, 1.0);
        return clamp(c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * (c5 + t * c6))))), 0.0, 1.0);
      }
      void main() {
        gl_Position = matrix * vec4(position, 1.0);
        if (byHeight > 0.5 && position.z > zCut) gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
        gl_PointSize = pointSize;
        vColor = byHeight > 0.5 ? viridis((position.z - zLo) / (zHi - zLo)) : color;
      }`;
    const fs = `
      precision mediump float;
      uniform float round;
      varying vec3 vColor;
      void main() {
        if (round > 0.5 && length(gl_PointCoord - vec2(0.5)) > 0.5) discard;
        gl_FragColor = vec4(vColor, 1.0);
      }`;
    function shader(type, source) {
      const s = gl.createShader(type);
      gl.shaderSource(s, source);
      gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
      return s;
    }
    try {
      program = gl.createProgram();
      gl.attachShader(program, shader(gl.VERTEX_SHADER, vs));
      gl.attachShader(program, shader(gl.FRAGMENT_SHADER, fs));
      gl.linkProgram(program);
      if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(program));
      const buffer = (array) => { const b = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, b); gl.bufferData(gl.ARRAY_BUFFER, array, gl.STATIC_DRAW); return b; };
      pointBuffer = buffer(points);
      nodeBuffer = buffer(nodes);
      // The trajectory as a dense row of dots: WebGL lines are one pixel wide.
      const trail = [];
      for (let i = 3; i < nodes.length; i += 3) {
        const d = Math.hypot(nodes[i] - nodes[i - 3], nodes[i + 1] - nodes[i - 2], nodes[i + 2] - nodes[i - 1]);
        const n = Math.min(2000, Math.max(1, Math.ceil(d / (DATA.extent / 400))));
        for (let k = 0; k < n; k++)
          for (let j = 0; j < 3; j++) trail.push(nodes[i - 3 + j] + (nodes[i + j] - nodes[i - 3 + j]) * k / n);
      }
      trailBuffer = buffer(new Float32Array(trail));
      trailCount = trail.length / 3;
      const loopArray = new Float32Array(DATA.loops.length * 6);
      DATA.loops.forEach(function (pair, i) {
        for (let e = 0; e < 2; e++) for (let k = 0; k < 3; k++) loopArray[i * 6 + e * 3 + k] = nodes[pair[e] * 3 + k];
      });
      loopCount = DATA.loops.length * 2;
      loopBuffer = buffer(loopArray);
    } catch (e) {
      console.log("WebGL unusable, drawing in 2D: " + e);
      gl = null;
    }
  }

  function drawGL(m, width, height) {
    glCanvas.width = width; glCanvas.height = height;
    gl.viewport(0, 0, width, height);
    gl.clearColor(1, 1, 1, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    gl.useProgram(program);
    const u = (name) => gl.getUniformLocation(program, name);
    gl.uniformMatrix4fv(u("matrix"), false, m);
    gl.uniform1f(u("zLo"), DATA.zLo);
    gl.uniform1f(u("zHi"), DATA.zHi);
    gl.uniform1f(u("zCut"), view.showCeiling ? 1e9 : DATA.zCut);
    const position = gl.getAttribLocation(program, "position");
    const draw = (buffer, mode, count, size, byHeight, color) => {
      gl.uniform1f(u("round"), byHeight > 0.5 ? 0 : 1);
      gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
      gl.enableVertexAttribArray(position);
      gl.vertexAttribPointer(position, 3, gl.FLOAT, false, 0, 0);
      gl.uniform1f(u("pointSize"), size);
      gl.uniform1f(u("byHeight"), byHeight);
      gl.uniform3fv(u("color"), color);
      gl.drawArrays(mode, 0, count);
    };
    const dpr = window.devicePixelRatio || 1;
    draw(pointBuffer, gl.POINTS, points.length / 3, 2.0 * dpr, 1, [0, 0, 0]);
    gl.disable(gl.DEPTH_TEST);
    if (loopCount > 0) draw(loopBuffer, gl.LINES, loopCount, 1, 0, [0.9, 0.0, 0.9]);
    if (trailCount > 0) draw(trailBuffer, gl.POINTS, trailCount, 3 * dpr, 0, [0.86, 0.08, 0.24]);
    draw(nodeBuffer, gl.POINTS, nodes.length / 3, 12 * dpr, 0, [0.1, 0.1, 0.1]);
    draw(nodeBuffer, gl.POINTS, nodes.length / 3, 8 * dpr, 0, [0.86, 0.08, 0.24]);
  }

  function draw2D(m, width, height) {
    // No WebGL: the same projection, far points first.
    ctx2d.fillStyle = "#ffffff";
    ctx2d.fillRect(0, 0, width, height);
    const cut = view.showCeiling ? 1e9 : DATA.zCut;
    const projected = [];
    for (let i = 0; i < points.length; i += 3) {
      if (points[i + 2] > cut) continue;
      const p = project(m, points[i], points[i + 1], points[i + 2], width, height);
      if (p && p[0] >= 0 && p[1] >= 0 && p[0] < width && p[1] < height) projected.push([p[0], p[1], p[2], points[i + 2]]);
    }
    projected.sort(function (a, b) { return b[2] - a[2]; });
    const size = Math.max(1.5, 2 * (window.devicePixelRatio || 1));
    for (const p of projected) {
      const c = viridis((p[3] - DATA.zLo) / (DATA.zHi - DATA.zLo));
      ctx2d.fillStyle = "rgb(" + c[0] + "," + c[1] + "," + c[2] + ")";
      ctx2d.fillRect(p[0] - size / 2, p[1] - size / 2, size, size);
    }
    const nodePx = [];
    for (let i = 0; i < nodes.length; i += 3) nodePx.push(project(m, nodes[i], nodes[i + 1], nodes[i + 2], width, height));
    ctx2d.strokeStyle = "#dc143c"; ctx2d.lineWidth = 3;
    ctx2d.beginPath();
    nodePx.forEach(function (p, i) { if (p) { if (i === 0) ctx2d.moveTo(p[0], p[1]); else ctx2d.lineTo(p[0], p[1]); } });
    ctx2d.stroke();
    ctx2d.strokeStyle = "#e600e6"; ctx2d.setLineDash([8, 5]);
    for (const pair of DATA.loops) {
      const a = nodePx[pair[0]], b = nodePx[pair[1]];
      if (a && b) { ctx2d.beginPath(); ctx2d.moveTo(a[0], a[1]); ctx2d.lineTo(b[0], b[1]); ctx2d.stroke(); }
    }
    ctx2d.setLineDash([]);
    ctx2d.fillStyle = "#dc143c";
    for (const p of nodePx) if (p) { ctx2d.beginPath(); ctx2d.arc(p[0], p[1], 5, 0, 2 * Math.PI); ctx2d.fill(); }
  }

  function drawOverlay(m, width, height, dpr) {
    if (gl) ctx2d.clearRect(0, 0, width, height);
    ctx2d.save();
    ctx2d.scale(dpr, dpr);
    const w = width / dpr, h = height / dpr;
    // Node numbers.
    ctx2d.font = "bold 13px sans-serif";
    ctx2d.textBaseline = "bottom";
    const every = Math.max(1, Math.ceil(nodes.length / 3 / 40));
    const STATUS_COLOUR = { recovered: "#b35c00", relocalized: "#1f4fbf", new_segment: "#c00018", doubtful: "#7a4a00" };
    const counts = {};
    for (let i = 0; i < nodes.length / 3; i++) {
      const status = DATA.status[i] || "";
      if (status) counts[status] = (counts[status] || 0) + 1;
      const marked = status in STATUS_COLOUR;
      if (!marked && i % every !== 0 && i !== nodes.length / 3 - 1) continue;
      const p = project(m, nodes[3 * i], nodes[3 * i + 1], nodes[3 * i + 2], width, height);
      if (!p) continue;
      const label = marked ? i + " " + status.replace("_", " ") : String(i);
      const x = p[0] / dpr + 7, y = p[1] / dpr - 5;
      ctx2d.fillStyle = "rgba(255,255,255,0.8)";
      ctx2d.fillRect(x - 2, y - 15, ctx2d.measureText(label).width + 4, 16);
      ctx2d.fillStyle = marked ? STATUS_COLOUR[status] : "#111111";
      ctx2d.fillText(label, x, y);
    }
    // Title and help.
    ctx2d.textBaseline = "top";
    ctx2d.fillStyle = "#111111";
    ctx2d.font = "bold 16px sans-serif";
    ctx2d.fillText(DATA.title, 12, 10);
    ctx2d.font = "13px sans-serif";
    ctx2d.fillText(DATA.shownCount + " of " + DATA.pointCount + " points, " + nodes.length / 3 + " nodes, " +
      DATA.loops.length + " loop closures" + (gl ? "" : " (2D fallback: no WebGL)"), 12, 32);
    ctx2d.fillText("drag: orbit, wheel: zoom, shift/right-drag: pan, c: ceiling " +
      (view.showCeiling ? "shown" : "hidden") + ", r: reset", 12, 50);
    const tally = Object.keys(counts).map(function (k) { return counts[k] + " " + k.replace("_", " "); });
    if (tally.length) ctx2d.fillText("stops: " + tally.join(", "), 12, 68);
    // Colour bar.
    const bx = w - 70, by = 40, bh = Math.min(240, h - 100);
    for (let y = 0; y < bh; y++) {
      const c = viridis(1 - y / bh);
      ctx2d.fillStyle = "rgb(" + c[0] + "," + c[1] + "," + c[2] + ")";
      ctx2d.fillRect(bx, by + y, 18, 1);
    }
    ctx2d.strokeStyle = "#111111"; ctx2d.lineWidth = 1;
    ctx2d.strokeRect(bx - 0.5, by - 0.5, 19, bh + 1);
    ctx2d.fillStyle = "#111111";
    ctx2d.textBaseline = "middle";
    const zLo = DATA.zLo + DATA.center[2], zHi = DATA.zHi + DATA.center[2];
    ctx2d.fillText(zHi.toFixed(1) + " m", bx + 22, by);
    ctx2d.fillText(zLo.toFixed(1) + " m", bx + 22, by + bh);
    ctx2d.textBaseline = "bottom";
    ctx2d.fillText("height", bx - 6, by - 6);
    ctx2d.restore();
  }

  function render() {
    const dpr = window.devicePixelRatio || 1;
    const width = Math.max(1, Math.round(window.innerWidth * dpr));
    const height = Math.max(1, Math.round(window.innerHeight * dpr));
    overlay.width = width; overlay.height = height;
    const m = matrix(width, height);
    if (gl) drawGL(m, width, height); else draw2D(m, width, height);
    drawOverlay(m, width, height, dpr);
  }
  let pending = false;
  function schedule() {
    if (!pending) { pending = true; requestAnimationFrame(function () { pending = false; render(); }); }
  }

  let drag = null;
  glCanvas.addEventListener("contextmenu", function (e) { e.preventDefault(); });
  glCanvas.addEventListener("mousedown", function (e) {
    drag = { x: e.clientX, y: e.clientY, pan: e.shiftKey || e.button === 2 };
  });
  window.addEventListener("mouseup", function () { drag = null; });
  window.addEventListener("mousemove", function (e) {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.x = e.clientX; drag.y = e.clientY;
    if (drag.pan) {
      const s = view.distance / window.innerHeight;
      const cy = Math.cos(view.yaw), sy = Math.sin(view.yaw);
      view.target[0] += s * dx * sy;
      view.target[1] -= s * dx * cy;
      view.target[2] += s * dy;
    } else {
      view.yaw -= dx * 0.01;
      view.pitch = Math.min(1.55, Math.max(-1.55, view.pitch + dy * 0.01));
    }
    schedule();
  });
  glCanvas.addEventListener("wheel", function (e) {
    e.preventDefault();
    view.distance *= Math.exp(e.deltaY * 0.001);
    schedule();
  }, { passive: false });
  window.addEventListener("keydown", function (e) {
    if (e.key === "c") { view.showCeiling = !view.showCeiling; schedule(); }
    if (e.key === "r") { Object.assign(view, JSON.parse(JSON.stringify(home))); schedule(); }
  });
  window.addEventListener("resize", schedule);
  render();
})();
</script>
</body>
</html>
"##;
