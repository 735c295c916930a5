// woundsweep 3D view: reads the JSON in #wsdata (see woundsweep/viz/view.py) and draws the
// deformed surface with plotly.js (Mesh3d, one colour per triangle), the closure zone's
// outline and the maximum's marker; the stage selector redraws with Plotly.react.
(function () {
  "use strict";
  var el = document.getElementById("wsdata");
  if (!el || typeof Plotly === "undefined") { return; }
  var D = JSON.parse(el.textContent);

  function bytes(b64) {
    var s = atob(b64), u = new Uint8Array(s.length);
    for (var i = 0; i < s.length; i++) { u[i] = s.charCodeAt(i); }
    return u.buffer;
  }
  function f32(b64) { return new Float32Array(bytes(b64)); }
  function i32(b64) { return new Int32Array(bytes(b64)); }

  var X = f32(D.x), Y = f32(D.y), Z = f32(D.z), T = i32(D.tri), E = i32(D.outline);
  var nT = D.n_triangles, I = new Int32Array(nT), J = new Int32Array(nT), K = new Int32Array(nT);
  for (var t = 0; t < nT; t++) { I[t] = T[3 * t]; J[t] = T[3 * t + 1]; K[t] = T[3 * t + 2]; }

  var select = document.getElementById("stage");
  var clip = document.getElementById("clip");
  var seethrough = document.getElementById("seethrough");
  var note = document.getElementById("note");
  var last = -1;
  D.stages.forEach(function (s, n) {
    var o = document.createElement("option");
    o.value = String(n);
    o.textContent = s.label + (s.stored ? "" : " (" + (s.reason || "no field") + ")");
    o.disabled = !s.stored;
    select.appendChild(o);
    if (s.stored) { last = n; }
  });

  function deformed(s) {
    var u = f32(s.u), n = X.length;
    var x = new Float32Array(n), y = new Float32Array(n), z = new Float32Array(n);
    for (var i = 0; i < n; i++) { x[i] = X[i] + u[3 * i]; y[i] = Y[i] + u[3 * i + 1]; z[i] = Z[i] + u[3 * i + 2]; }
    return [x, y, z];
  }

  function outline(p) {
    var x = [], y = [], z = [];
    for (var e = 0; e < E.length; e += 2) {
      x.push(p[0][E[e]], p[0][E[e + 1]], null);
      y.push(p[1][E[e]], p[1][E[e + 1]], null);
      z.push(p[2][E[e]], p[2][E[e + 1]], null);
    }
    return { type: "scatter3d", mode: "lines", x: x, y: y, z: z, name: "closure zone",
             line: { color: "black", width: 5 }, hoverinfo: "name" };
  }

  function draw() {
    var s = D.stages[Number(select.value)];
    if (!s || !s.stored) { return; }
    var p = deformed(s), vm = f32(s.vm), m = s.max;
    var top = clip.checked && s.p99_von_mises_kPa ? s.p99_von_mises_kPa : s.surface_max_kPa;
    var surface = {
      type: "mesh3d", x: p[0], y: p[1], z: p[2], i: I, j: J, k: K,
      intensity: vm, intensitymode: "cell", colorscale: "Viridis", cmin: 0, cmax: top,
      colorbar: { title: { text: "von Mises (kPa)" } }, flatshading: true,
      opacity: seethrough.checked ? 0.35 : 1, name: "surface",
      hovertemplate: "von Mises %{intensity:.4g} kPa<extra></extra>"
    };
    var marker = {
      type: "scatter3d", mode: "markers+text", name: "max von Mises",
      x: [m.deformed_mm[0]], y: [m.deformed_mm[1]], z: [m.deformed_mm[2]],
      text: ["max " + m.value_kPa.toPrecision(4) + " kPa"], textposition: "top center",
      marker: { symbol: "diamond", size: 7, color: "red" }, hoverinfo: "text"
    };
    var layout = {
      margin: { l: 0, r: 0, t: 30, b: 0 }, showlegend: true, legend: { x: 0, y: 1 },
      title: { text: "job " + D.job_index + ", " + s.label, font: { size: 14 } },
      uirevision: "keep-camera",
      scene: { aspectmode: "data", xaxis: { title: { text: "x (mm)" } },
               yaxis: { title: { text: "y (mm)" } }, zaxis: { title: { text: "z (mm)" } },
               camera: { eye: { x: 1.2, y: -1.6, z: 1.1 } } }
    };
    var traces = [surface, marker];
    if (E.length) { traces.splice(1, 0, outline(p)); }
    note.textContent = "max " + m.value_kPa.toPrecision(4) + " kPa at (" +
      m.reference_mm.map(function (c) { return c.toFixed(3); }).join(", ") + ") mm (reference)";
    Plotly.react("plot", traces, layout, { responsive: true, displaylogo: false });
  }

  if (last < 0) {
    note.textContent = "no stage of this job has a stored field";
    select.disabled = true;
    return;
  }
  select.value = String(last);
  select.addEventListener("change", draw);
  clip.addEventListener("change", draw);
  seethrough.addEventListener("change", draw);
  draw();
})();
