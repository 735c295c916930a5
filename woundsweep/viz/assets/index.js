// woundsweep atlas index: the table of every job from the JSON in #atlasdata (see
// woundsweep/viz/atlas.py), sortable by any column, filtered per column, and drawn one page
// of rows at a time (page size 50-1,000), so that the paper's 11,664 jobs never become
// 11,664 DOM rows. The filtered and sorted rows are kept until a filter or the sort changes:
// turning a page only slices them. The state (sort, filters, page, page size) lives in the
// URL's #fragment, so the back button from a job page returns to the same rows.
(function () {
  "use strict";
  var D = JSON.parse(document.getElementById("atlasdata").textContent);
  var cols = D.columns, all = D.rows, SIZES = [50, 100, 200, 500, 1000];
  var table = document.getElementById("index"), pager = document.getElementById("pager");
  var pagerBottom = document.getElementById("pager-bottom");
  var state = { sort: 0, dir: 1, page: 0, size: 100, filters: cols.map(function () { return ""; }) };
  var view = null;  // the filtered, sorted rows (null: to recompute)

  function text(v) {
    if (v === null || v === undefined) { return "-"; }
    if (typeof v === "number") { return Number.isInteger(v) ? String(v) : String(+v.toPrecision(4)); }
    return String(v);
  }

  function count(n) { return n.toLocaleString("en-US"); }

  // A filter as a test of one cell: text = substring (case-insensitive); numbers: 2, >1,
  // <=0.5, 1..2; "-" = missing. Compiled once per change, not once per row.
  function compile(f, type) {
    if (!f) { return null; }
    if (f === "-") { return function (v) { return v === null; }; }
    if (type === "num") {
      // A number has at most one "." (so that "1..2" is a range, not the number 1).
      var num = "(-?(?:\\d+\\.?\\d*|\\.\\d+)(?:e[-+]?\\d+)?)";
      var m = new RegExp("^\\s*(<=|>=|<|>|=)?\\s*" + num + "\\s*(?:\\.\\.\\s*" + num + ")?\\s*$", "i").exec(f);
      if (m) {
        var a = parseFloat(m[2]), b = m[3] !== undefined ? parseFloat(m[3]) : null, op = m[1];
        return function (v) {
          if (v === null) { return false; }
          if (b !== null) { return v >= a && v <= b; }
          switch (op) {
            case "<": return v < a;
            case "<=": return v <= a;
            case ">": return v > a;
            case ">=": return v >= a;
            default: return Math.abs(v - a) <= 1e-9 * Math.max(1, Math.abs(a));
          }
        };
      }
    }
    var needle = f.toLowerCase();
    return function (v) { return text(v).toLowerCase().indexOf(needle) >= 0; };
  }

  function selected() {
    var tests = [];
    cols.forEach(function (col, c) {
      var t = compile(state.filters[c], col.type);
      if (t) { tests.push([c, t]); }
    });
    var rows = !tests.length ? all.slice() : all.filter(function (r) {
      for (var i = 0; i < tests.length; i++) {
        if (!tests[i][1](r[tests[i][0]])) { return false; }
      }
      return true;
    });
    var c = state.sort, d = state.dir;
    rows.sort(function (a, b) {  // missing values last in either direction; ties by job
      var x = a[c], y = b[c];
      if (x === y) { return a[0] - b[0]; }
      if (x === null) { return 1; }
      if (y === null) { return -1; }
      return (x < y ? -1 : 1) * d;
    });
    return rows;
  }

  // The state in the URL's #fragment: s=<column>&d=-1&p=<page, from 1>&n=<size>&f.<column>=..
  function readHash() {
    var q = new URLSearchParams(location.hash.slice(1));
    var keys = cols.map(function (c) { return c.key; });
    var s = keys.indexOf(q.get("s") || "");
    if (s >= 0) { state.sort = s; }
    state.dir = q.get("d") === "-1" ? -1 : 1;
    var n = parseInt(q.get("n"), 10);
    if (SIZES.indexOf(n) >= 0) { state.size = n; }
    var p = parseInt(q.get("p"), 10);
    state.page = p > 0 ? p - 1 : 0;
    keys.forEach(function (k, c) { state.filters[c] = (q.get("f." + k) || "").trim(); });
  }

  function writeHash() {
    var q = new URLSearchParams();
    if (state.sort !== 0) { q.set("s", cols[state.sort].key); }
    if (state.dir < 0) { q.set("d", "-1"); }
    if (state.page > 0) { q.set("p", String(state.page + 1)); }
    if (state.size !== 100) { q.set("n", String(state.size)); }
    cols.forEach(function (col, c) { if (state.filters[c]) { q.set("f." + col.key, state.filters[c]); } });
    var h = q.toString();
    if (h !== location.hash.slice(1)) {
      try { history.replaceState(null, "", h ? "#" + h : location.pathname); } catch (e) { /* no history API: the state stays on the page */ }
    }
  }

  var thead = document.createElement("thead"), tbody = document.createElement("tbody");
  var names = document.createElement("tr"), filters = document.createElement("tr");
  var inputs = [];
  filters.className = "filters";
  readHash();
  cols.forEach(function (col, c) {
    var th = document.createElement("th");
    th.textContent = col.label.replace(/_/g, "_\u200b");  // headers may wrap after "_"
    th.title = "sort by " + col.label;
    th.setAttribute("data-col", col.key);
    th.addEventListener("click", function () {
      state.dir = state.sort === c ? -state.dir : 1;
      state.sort = c;
      state.page = 0;
      view = null;
      render();
    });
    names.appendChild(th);
    var fh = document.createElement("th"), input = document.createElement("input");
    input.placeholder = col.type === "num" ? ">0" : "text";
    input.setAttribute("data-col", col.key);
    input.value = state.filters[c];
    input.addEventListener("input", function () {
      var f = input.value.trim();
      if (f === state.filters[c]) { return; }
      state.filters[c] = f;
      state.page = 0;
      view = null;
      render();
    });
    inputs.push(input);
    fh.appendChild(input);
    filters.appendChild(fh);
  });
  thead.appendChild(names);
  thead.appendChild(filters);
  table.appendChild(thead);
  table.appendChild(tbody);

  function goto(page) { state.page = page; render(); }

  function button(label, page, disabled, name) {
    var b = document.createElement("button");
    b.textContent = label;
    b.disabled = disabled;
    b.setAttribute("data-page", name);
    b.addEventListener("click", function () { goto(page); });
    return b;
  }

  // Page navigation: first, previous, "page [k] of N", next, last.
  function navigation(pages, withInput) {
    var nav = document.createElement("span"), p = state.page;
    nav.className = "nav";
    nav.appendChild(button("\u00ab first", 0, p === 0, "first"));
    nav.appendChild(button("\u2039 previous", p - 1, p === 0, "previous"));
    var where = document.createElement("span");
    where.className = "where";
    if (withInput) {
      var box = document.createElement("input");
      box.type = "number";
      box.min = "1";
      box.max = String(pages);
      box.value = String(p + 1);
      box.id = "pageno";
      box.title = "go to page";
      box.addEventListener("change", function () {
        var k = parseInt(box.value, 10);
        goto(Math.max(0, Math.min(pages - 1, (isNaN(k) ? 1 : k) - 1)));
      });
      where.appendChild(document.createTextNode("page "));
      where.appendChild(box);
      where.appendChild(document.createTextNode(" of " + count(pages)));
    } else {
      where.textContent = "page " + count(p + 1) + " of " + count(pages);
    }
    nav.appendChild(where);
    nav.appendChild(button("next \u203a", p + 1, p >= pages - 1, "next"));
    nav.appendChild(button("last \u00bb", pages - 1, p >= pages - 1, "last"));
    return nav;
  }

  function sizeSelector() {
    var label = document.createElement("label"), sel = document.createElement("select");
    sel.id = "pagesize";
    SIZES.forEach(function (n) {
      var o = document.createElement("option");
      o.value = String(n);
      o.textContent = String(n);
      o.selected = n === state.size;
      sel.appendChild(o);
    });
    sel.addEventListener("change", function () {
      var first = state.page * state.size;  // keep the first shown row in view
      state.size = parseInt(sel.value, 10);
      goto(Math.floor(first / state.size));
    });
    label.appendChild(document.createTextNode("rows per page "));
    label.appendChild(sel);
    return label;
  }

  function clearButton() {
    var b = document.createElement("button");
    b.textContent = "clear filters";
    b.id = "clearfilters";
    b.addEventListener("click", function () {
      state.filters = cols.map(function () { return ""; });
      inputs.forEach(function (i) { i.value = ""; });
      state.page = 0;
      view = null;
      render();
    });
    return b;
  }

  function render() {
    if (view === null) { view = selected(); }
    var n = view.length, pages = Math.max(1, Math.ceil(n / state.size));
    state.page = Math.max(0, Math.min(state.page, pages - 1));
    var start = state.page * state.size, shown = view.slice(start, start + state.size);
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
    var filtered = state.filters.some(function (f) { return f !== ""; });
    var info = document.createElement("span");
    info.id = "count";
    info.textContent = (n ? "rows " + count(start + 1) + "-" + count(start + shown.length) + " of " + count(n)
      : "no rows") + (filtered ? " (filtered from " + count(all.length) + ")" : "");
    pager.textContent = "";
    pager.appendChild(info);
    pager.appendChild(navigation(pages, true));
    pager.appendChild(sizeSelector());
    if (filtered) { pager.appendChild(clearButton()); }
    if (pagerBottom) {
      pagerBottom.textContent = "";
      if (pages > 1) { pagerBottom.appendChild(navigation(pages, false)); }
    }
    writeHash();
  }

  render();
})();
