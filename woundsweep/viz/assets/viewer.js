// woundsweep 3D view: reads the JSON in #wsdata (see woundsweep/viz/view.py) and draws the
// deformed surface with plotly.js (Mesh3d, one colour per triangle), optionally cut at the
// wound's mid-section, the closure zone's outline, the stage's extra lines (`traces`:
// threads, outlines, moved with the deformation scale), the maximum's marker, and beside it
// the von Mises along the stored profile lines; the controls redraw with Plotly.react.
(function () {
  "use strict";
  var el = document.getElementById("wsdata");
  if (!el || typeof Plotly === "undefined") { return; }
  var D = JSON.parse(el.textContent);
  // Cells above the colour scale's top (p99): pale to deep magenta up to the largest value,
  // so the band still shows where the wound's centre is highest.
  var OVER = ["#f7c6f5", "#ff00ff", "#8b008b"];
  var VIRIDIS = ["#440154", "#482878", "#3e4989", "#31688e", "#26828e", "#1f9e89",
                 "#35b779", "#6ece58", "#b5de2b", "#fde725"];

  function bytes(b64) {
    var s = atob(b64), u = new Uint8Array(s.length);
    for (var i = 0; i < s.length; i++) { u[i] = s.charCodeAt(i); }
    return u.buffer;
  }
  function f32(b64) { return new Float32Array(bytes(b64)); }
  function i32(b64) { return new Int32Array(bytes(b64)); }

  var X = f32(D.x), Y = f32(D.y), Z = f32(D.z), T = i32(D.tri), E = i32(D.outline);
  var C = D.cut, CX = f32(C.x), CY = f32(C.y), CZ = f32(C.z);
  var CA = i32(C.a), CB = i32(C.b), CT = f32(C.t), CTRI = i32(C.tri);
  var nT = D.n_triangles;
  // Surface triangles on the kept side of the cut (reference centroid y >= the cut's y).
  var kept = [];
  for (var t = 0; t < nT; t++) {
    var yc = (Y[T[3 * t]] + Y[T[3 * t + 1]] + Y[T[3 * t + 2]]) / 3;
    if (yc >= C.y_mm) { kept.push(t); }
  }

  var select = document.getElementById("stage");
  var scaleBox = document.getElementById("scale");
  var cutBox = document.getElementById("cut");
  var fullrange = document.getElementById("fullrange");
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

  function scale() {
    var v = Number(scaleBox.value);
    return isFinite(v) && v >= 0 ? v : 1;
  }

  function deformed(X0, Y0, Z0, u, k) {
    var n = X0.length, x = new Float32Array(n), y = new Float32Array(n), z = new Float32Array(n);
    for (var i = 0; i < n; i++) {
      x[i] = X0[i] + k * u[3 * i]; y[i] = Y0[i] + k * u[3 * i + 1]; z[i] = Z0[i] + k * u[3 * i + 2];
    }
    return [x, y, z];
  }

  function outline(p, cut) {
    var x = [], y = [], z = [];
    for (var e = 0; e < E.length; e += 2) {
      if (cut && Y[E[e]] < C.y_mm && Y[E[e + 1]] < C.y_mm) { continue; }
      x.push(p[0][E[e]], p[0][E[e + 1]], null);
      y.push(p[1][E[e]], p[1][E[e + 1]], null);
      z.push(p[2][E[e]], p[2][E[e + 1]], null);
    }
    return { type: "scatter3d", mode: "lines", x: x, y: y, z: z, name: "closure zone",
             line: { color: "black", width: 5 }, hoverinfo: "name" };
  }

  // A stage's extra lines: reference points plus k times their displacement, pieces between
  // nulls; with the cut a piece wholly on the cut-away side (y < the cut's) is left out. One
  // legend entry per group, the trace's name on hover.
  function extraLines(s, k, cut) {
    var seen = {};
    return (s.traces || []).map(function (t) {
      var x = [], y = [], z = [], piece = [], keep = false;
      function flush() {
        if (piece.length && (!cut || keep)) {
          piece.forEach(function (i) {
            x.push(t.x[i] + k * t.ux[i]); y.push(t.y[i] + k * t.uy[i]); z.push(t.z[i] + k * t.uz[i]);
          });
          x.push(null); y.push(null); z.push(null);
        }
        piece = []; keep = false;
      }
      for (var i = 0; i < t.x.length; i++) {
        if (t.x[i] === null) { flush(); continue; }
        piece.push(i);
        if (t.y[i] >= C.y_mm) { keep = true; }
      }
      flush();
      var group = t.group || t.name, first = x.length > 0 && !seen[group];
      if (first) { seen[group] = true; }
      return { type: "scatter3d", mode: "lines", x: x, y: y, z: z, name: group,
               legendgroup: group, showlegend: first, text: t.name, hoverinfo: "text",
               line: { color: t.color, width: t.width } };
    });
  }

  // The colour scale: Viridis up to `top`, then a band of shades of magenta for the values
  // above it, [top, max] mapped linearly onto [top, 1.15 top] (`shade`).
  function colours(top, max) {
    if (!(max > top)) {
      return { cmax: top, scale: VIRIDIS.map(function (c, i) { return [i / (VIRIDIS.length - 1), c]; }),
               ticks: null, shade: function (v) { return Math.min(v, top); } };
    }
    var cmax = top * 1.15, f = top / cmax, scale = [];
    VIRIDIS.forEach(function (c, i) { scale.push([f * i / (VIRIDIS.length - 1), c]); });
    OVER.forEach(function (c, i) { scale.push([f + (1 - f) * i / (OVER.length - 1), c]); });
    var vals = [], text = [], step = niceStep(top / 5);
    for (var v = 0; v <= top * 0.93; v += step) { vals.push(v); text.push(String(+v.toPrecision(4))); }
    vals.push(top, cmax);
    text.push("p99 " + top.toPrecision(3), "max " + max.toPrecision(3));
    return { cmax: cmax, scale: scale, ticks: [vals, text], shade: function (v) {
      return v <= top ? v : top + (Math.min(v, max) - top) / (max - top) * (cmax - top);
    } };
  }

  function niceStep(x) {
    var p = Math.pow(10, Math.floor(Math.log10(x))), m = x / p;
    return (m < 1.5 ? 1 : m < 3.5 ? 2 : m < 7.5 ? 5 : 10) * p;
  }

  function draw() {
    var s = D.stages[Number(select.value)];
    if (!s || !s.stored) { return; }
    var k = scale(), u = f32(s.u), vm = f32(s.vm), m = s.max;
    var p = deformed(X, Y, Z, u, k);
    var top = !fullrange.checked && s.p99_von_mises_kPa ? s.p99_von_mises_kPa : s.surface_max_kPa;
    var I = [], J = [], K = [], V = [], px = Array.from(p[0]), py = Array.from(p[1]), pz = Array.from(p[2]);
    var tris = cutBox.checked ? kept : null, n = tris ? tris.length : nT;
    for (var q = 0; q < n; q++) {
      var t = tris ? tris[q] : q;
      I.push(T[3 * t]); J.push(T[3 * t + 1]); K.push(T[3 * t + 2]); V.push(vm[t]);
    }
    if (cutBox.checked) {  // the cut face: points on mesh edges, moved with their edge
      var cu = f32(s.cut_u), cvm = f32(s.cut_vm), base = px.length, ne = CA.length;
      for (var e = 0; e < ne; e++) {
        var a = CA[e], b = CB[e], w = CT[e];
        px.push((1 - w) * (CX[a] + k * cu[3 * a]) + w * (CX[b] + k * cu[3 * b]));
        py.push((1 - w) * (CY[a] + k * cu[3 * a + 1]) + w * (CY[b] + k * cu[3 * b + 1]));
        pz.push((1 - w) * (CZ[a] + k * cu[3 * a + 2]) + w * (CZ[b] + k * cu[3 * b + 2]));
      }
      for (var c = 0; c < C.n_triangles; c++) {
        I.push(base + CTRI[3 * c]); J.push(base + CTRI[3 * c + 1]); K.push(base + CTRI[3 * c + 2]);
        V.push(cvm[c]);
      }
    }
    var col = colours(top, s.surface_max_kPa);
    var shown = V.map(col.shade);
    var bar = { title: { text: "von Mises, cell mean (kPa)" } };
    if (col.ticks) { bar.tickvals = col.ticks[0]; bar.ticktext = col.ticks[1]; }
    var surface = {
      type: "mesh3d", x: px, y: py, z: pz, i: I, j: J, k: K,
      intensity: shown, intensitymode: "cell", colorscale: col.scale, cmin: 0, cmax: col.cmax,
      colorbar: bar, flatshading: true, customdata: V,
      opacity: seethrough.checked ? 0.35 : 1, name: "surface",
      hovertemplate: "von Mises %{customdata:.4g} kPa<extra></extra>"
    };
    var mx = m.reference_mm.map(function (c, i) { return c + k * (m.deformed_mm[i] - c); });
    var marker = {
      type: "scatter3d", mode: "markers", name: "largest cell mean",
      x: [mx[0]], y: [mx[1]], z: [mx[2]],
      text: ["largest cell mean " + m.value_kPa.toPrecision(4) + " kPa"],
      marker: { symbol: "diamond", size: 5, color: "red" }, hoverinfo: "text"
    };
    var head = D.title === null || D.title === undefined ? "job " + D.job_index : D.title;
    var layout = {
      margin: { l: 0, r: 0, t: 30, b: 0 }, showlegend: true, legend: { x: 0, y: 1 },
      title: { text: (head ? head + ", " : "") + s.label + (D.element ? " (" + D.element + ")" : ""),
               font: { size: 14 }, x: 0.01, xanchor: "left" },
      uirevision: "keep-camera",
      scene: { aspectmode: "data", xaxis: { title: { text: "x (mm)" } },
               yaxis: { title: { text: "y (mm)" } }, zaxis: { title: { text: "z (mm)" } },
               camera: D.camera || { eye: { x: 1.2, y: -1.6, z: 1.1 } } }
    };
    var traces = [surface].concat(extraLines(s, k, cutBox.checked), [marker]);
    if (E.length) { traces.splice(1, 0, outline(p, cutBox.checked)); }
    note.textContent = "von Mises: largest cell mean " + m.value_kPa.toPrecision(4) + " kPa at (" +
      m.reference_mm.map(function (c) { return c.toFixed(3); }).join(", ") + ") mm (reference)" +
      (s.p99_von_mises_kPa ? "; p99 of the volume " + s.p99_von_mises_kPa.toPrecision(4) + " kPa" : "") +
      (s.max_von_mises_kPa ? "; largest sample " + s.max_von_mises_kPa.toPrecision(4) + " kPa" : "");
    Plotly.react("plot", traces, layout, { responsive: true, displaylogo: false });
    drawLines(s, top);
  }

  function drawLines(s, top) {
    var lines = s.lines || [];
    var traces = lines.map(function (l) {
      return { type: "scatter", mode: "lines", name: l.name.replace(/_/g, " "), x: l.s_mm,
               y: l.von_mises_kPa, connectgaps: false,
               hovertemplate: l.name + ": %{y:.4g} kPa at %{x:.3g} mm<extra></extra>" };
    });
    var layout = {
      margin: { l: 55, r: 10, t: 30, b: 45 },
      title: { text: lines.length ? "von Mises along the profile lines" : "no profile lines stored",
               font: { size: 14 } },
      xaxis: { title: { text: "distance along the line (mm)" } },
      yaxis: { title: { text: "von Mises (kPa)" }, rangemode: "tozero" },
      legend: { x: 1.02, y: 1, xanchor: "left", yanchor: "top" },  // beside, not under
      shapes: top ? [{ type: "line", xref: "paper", x0: 0, x1: 1, y0: top, y1: top,
                       line: { color: "#999", dash: "dot", width: 1 } }] : []
    };
    Plotly.react("lines", traces, layout, { responsive: true, displayModeBar: false });
    drawClosure(s);
  }

  function drawClosure(s) {
    var c = s.closure;
    var traces = c ? [
      { type: "scatter", mode: "lines+markers", name: "closing force", x: c.closure_line_y_mm,
        y: c.closing_force_per_length_mN_per_mm, line: { shape: "hvh" },
        hovertemplate: "closing: %{y:.4g} mN/mm at y = %{x:.3g} mm<extra></extra>" },
      { type: "scatter", mode: "lines+markers", name: "contact force", x: c.closure_line_y_mm,
        y: c.contact_force_per_length_mN_per_mm, line: { shape: "hvh" },
        hovertemplate: "contact: %{y:.4g} mN/mm at y = %{x:.3g} mm<extra></extra>" }
    ] : [];
    var layout = {
      margin: { l: 55, r: 10, t: 30, b: 45 },
      title: { text: c ? "forces per length along the wound" : "no line loads stored",
               font: { size: 14 } },
      xaxis: { title: { text: "y along the wound (mm)" } },
      yaxis: { title: { text: "mN/mm" }, rangemode: "tozero" },
      legend: { x: 1.02, y: 1, xanchor: "left", yanchor: "top" }
    };
    Plotly.react("closure", traces, layout, { responsive: true, displayModeBar: false });
  }

  if (last < 0) {
    note.textContent = "no stage of this job has a stored field";
    select.disabled = true;
    return;
  }
  var first = D.initial === null || D.initial === undefined ? -1 :
    D.stages.findIndex(function (s) { return s.stage === D.initial && s.stored; });
  select.value = String(first >= 0 ? first : last);
  [select, cutBox, fullrange, seethrough].forEach(function (b) { b.addEventListener("change", draw); });
  scaleBox.addEventListener("input", draw);
  draw();
})();
