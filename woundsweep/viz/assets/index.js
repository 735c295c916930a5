// woundsweep atlas index: the table of every job from the JSON in #atlasdata (see
// woundsweep/viz/atlas.py), sortable by any column, filtered per column, drawn a page of
// rows at a time so that the paper's 11,664 jobs stay quick.
(function () {
  "use strict";
  var D = JSON.parse(document.getElementById("atlasdata").textContent);
  var cols = D.columns, all = D.rows, PAGE = 200;
  var table = document.getElementById("index"), pager = document.getElementById("pager");
  var state = { sort: 0, dir: 1, page: 0, filters: cols.map(function () { return ""; }) };

  function text(v) {
    if (v === null || v === undefined) { return "-"; }
    if (typeof v === "number") { return Number.isInteger(v) ? String(v) : String(+v.toPrecision(4)); }
    return String(v);
  }

  // A filter: text = substring (case-insensitive); numbers: 2, >1, <=0.5, 1..2; "-" = missing.
  function test(f, v, type) {
    if (!f) { return true; }
    if (f === "-") { return v === null; }
    if (type === "num") {
      var m = /^\s*(<=|>=|<|>|=)?\s*(-?[\d.]+(?:e-?\d+)?)\s*(?:\.\.\s*(-?[\d.]+(?:e-?\d+)?))?\s*$/i.exec(f);
      if (m) {
        if (v === null) { return false; }
        var a = parseFloat(m[2]);
        if (m[3] !== undefined) { return v >= a && v <= parseFloat(m[3]); }
        switch (m[1]) {
          case "<": return v < a;
          case "<=": return v <= a;
          case ">": return v > a;
          case ">=": return v >= a;
          default: return Math.abs(v - a) <= 1e-9 * Math.max(1, Math.abs(a));
        }
      }
    }
    return text(v).toLowerCase().indexOf(f.toLowerCase()) >= 0;
  }

  function selected() {
    var rows = all.filter(function (r) {
      for (var c = 0; c < cols.length; c++) {
        if (!test(state.filters[c], r[c], cols[c].type)) { return false; }
      }
      return true;
    });
    var c = state.sort, d = state.dir;
    rows.sort(function (a, b) {
      var x = a[c], y = b[c];
      if (x === y) { return a[0] - b[0]; }
      if (x === null) { return 1; }
      if (y === null) { return -1; }
      return (x < y ? -1 : 1) * d;
    });
    return rows;
  }

  var thead = document.createElement("thead"), tbody = document.createElement("tbody");
  var names = document.createElement("tr"), filters = document.createElement("tr");
  filters.className = "filters";
  cols.forEach(function (col, c) {
    var th = document.createElement("th");
    th.textContent = col.label.replace(/_/g, "_\u200b");  // headers may wrap after "_"
    th.title = "sort by " + col.label;
    th.setAttribute("data-col", col.key);
    th.addEventListener("click", function () {
      state.dir = state.sort === c ? -state.dir : 1;
      state.sort = c;
      state.page = 0;
      render();
    });
    names.appendChild(th);
    var fh = document.createElement("th"), input = document.createElement("input");
    input.placeholder = col.type === "num" ? ">0" : "text";
    input.setAttribute("data-col", col.key);
    input.addEventListener("input", function () { state.filters[c] = input.value.trim(); state.page = 0; render(); });
    fh.appendChild(input);
    filters.appendChild(fh);
  });
  thead.appendChild(names);
  thead.appendChild(filters);
  table.appendChild(thead);
  table.appendChild(tbody);

  function button(label, page, disabled) {
    var b = document.createElement("button");
    b.textContent = label;
    b.disabled = disabled;
    b.addEventListener("click", function () { state.page = page; render(); });
    return b;
  }

  function render() {
    var rows = selected(), pages = Math.max(1, Math.ceil(rows.length / PAGE));
    state.page = Math.min(state.page, pages - 1);
    var start = state.page * PAGE, shown = rows.slice(start, start + PAGE);
    Array.prototype.forEach.call(names.children, function (th, c) {
      th.className = c === state.sort ? (state.dir > 0 ? "asc" : "desc") : "";
    });
    var failed = cols.findIndex(function (c) { return c.key === "failure_class"; });
    var html = [];
    shown.forEach(function (r) {
      var cells = r.map(function (v, c) {
        var t = text(v).replace(/&/g, "&amp;").replace(/</g, "&lt;");
        if (c === 0) { t = '<a href="jobs/job-' + r[0] + '.html">' + t + "</a>"; }
        var cls = c === failed && v !== "converged" ? ' class="failed"' : "";
        return "<td" + cls + ">" + t + "</td>";
      });
      html.push('<tr data-job="' + r[0] + '">' + cells.join("") + "</tr>");
    });
    tbody.innerHTML = html.join("");
    pager.textContent = "";
    var info = document.createElement("span");
    info.id = "count";
    info.textContent = rows.length + " of " + all.length + " jobs" +
      (rows.length > PAGE ? "; rows " + (start + 1) + "-" + (start + shown.length) : "");
    pager.appendChild(info);
    if (pages > 1) {
      pager.appendChild(button("first", 0, state.page === 0));
      pager.appendChild(button("previous", state.page - 1, state.page === 0));
      pager.appendChild(button("next", state.page + 1, state.page >= pages - 1));
      pager.appendChild(button("last", pages - 1, state.page >= pages - 1));
    }
  }

  render();
})();
