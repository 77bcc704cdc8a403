/* One time axis for the report's figures (inlined by logscan/report/page.py).
   Every div.ls-timeseries follows the x range of the one zoomed or panned; a row with
   data-start/data-end (incidents, alarms) zooms them all to its interval with a margin of
   max(2 s, 50 % of its span), by click or Enter, and so does a click on an incident marker of the
   path figure (#ctx-path, customdata [start, end]); "reset zoom" restores each figure's first view.
   Times on the axis are in the log's clock; a UTC clock is a date axis counting milliseconds
   (<body data-time-scale="1000">: axis units per second), whose ranges plotly gives as date strings.
   Feedback guard: a follower's own plotly_relayout echoes the range already shared, and is
   ignored while the followers are being moved. A detector section is one figure (its rows share
   one x axis, one spike line across them), so a zoom is one relayout per section; sections folded
   away follow when opened. */
(function () {
  "use strict";
  var MIN_MARGIN_S = 2, MARGIN_FRACTION = 0.5;
  var shared = "auto", syncing = 0, initial = [], full = "auto", label, button;
  var scale = Number(document.body.getAttribute("data-time-scale")) || 1;  // axis units per second

  /* An axis value as a number: a date axis' "2024-03-18 14:49:30.5" as epoch milliseconds (UTC). */
  function axisNumber(value) {
    if (typeof value !== "string") { return Number(value); }
    var iso = value.replace(" ", "T");
    return Date.parse(/(Z|[+-]\d\d:?\d\d)$/.test(iso) ? iso : iso + "Z");
  }
  function timeText(value) {
    return scale === 1000 ? new Date(value).toISOString().slice(11, 23) : value.toFixed(2);
  }

  function plots() {
    return Array.prototype.filter.call(document.querySelectorAll(".ls-timeseries"), function (el) {
      return el._fullLayout && el._fullLayout.xaxis;
    });
  }
  function fail(err) { window.logscanError("zoom failed: " + (err && err.message ? err.message : err)); }
  function rangeOf(el) {
    var x = el.layout.xaxis;
    return x.autorange || !x.range ? "auto" : [axisNumber(x.range[0]), axisNumber(x.range[1])];
  }
  function same(a, b) {
    if (a === "auto" || b === "auto") { return a === b; }
    var tol = 1e-9 * (Math.abs(a[1] - a[0]) + 1);
    return Math.abs(a[0] - b[0]) <= tol && Math.abs(a[1] - b[1]) <= tol;
  }
  function show(range) {
    var zoomed = range !== "auto" && !same(range, full);
    var unit = scale === 1000 ? " UTC" : " s";
    label.textContent = zoomed ? "time " + timeText(range[0]) + " to " + timeText(range[1]) + unit : "full time range";
    button.disabled = !zoomed;
  }
  function folded(el) { return !!el.closest("details:not([open])"); }
  function xUpdate(range) { return range === "auto" ? { "xaxis.autorange": true } : { "xaxis.range": range.slice() }; }
  /* Moves every figure but `source` to `range` ("auto": autorange), in one pass: one relayout per
     figure (a section is one figure, its rows on one axis); a figure in a folded section is moved
     when the section opens (`catchUp`). */
  function share(range, source) {
    shared = range;
    show(range);
    var update = xUpdate(range);
    syncing += 1;
    var jobs = [];
    plots().forEach(function (el) {
      if (el === source) { return; }
      if (folded(el)) { el.lsStale = true; return; }
      el.lsStale = false;
      jobs.push(Plotly.relayout(el, update));
    });
    return Promise.all(jobs).then(function () { syncing -= 1; }, function (err) { syncing -= 1; fail(err); });
  }
  function catchUp(section) {
    if (!section.open) { return; }
    var stale = Array.prototype.filter.call(section.querySelectorAll(".ls-timeseries"), function (el) {
      return el.lsStale && el._fullLayout;
    });
    if (!stale.length) { return; }
    syncing += 1;
    var jobs = stale.map(function (el) { el.lsStale = false; return Plotly.relayout(el, xUpdate(shared)); });
    Promise.all(jobs).then(function () { syncing -= 1; }, function (err) { syncing -= 1; fail(err); });
  }
  function follow(el) {
    el.on("plotly_relayout", function (event) {
      var keys = Object.keys(event || {}).join(" ");
      if (syncing || !/xaxis\.(range|autorange)/.test(keys)) { return; }
      var range = rangeOf(el);
      if (!same(range, shared)) { share(range, el); }
    });
  }
  function zoomTo(start, end) {
    var margin = Math.max(MIN_MARGIN_S * scale, MARGIN_FRACTION * (end - start));
    var range = [start - margin, end + margin];
    if (full !== "auto") { range = [Math.max(range[0], full[0]), Math.min(range[1], full[1])]; }
    return share(range, null);
  }
  function reset() {
    shared = "auto";
    show("auto");
    syncing += 1;
    var jobs = initial.map(function (view) {
      var update = { "xaxis.range": view.x === "auto" ? null : view.x.slice(), "xaxis.autorange": view.x === "auto" };
      view.y.forEach(function (axis) {  // every row's y axis
        update[axis.auto ? axis.key + ".autorange" : axis.key + ".range"] = axis.auto ? true : axis.range.slice();
      });
      view.el.lsStale = false;
      return Plotly.relayout(view.el, update);
    });
    return Promise.all(jobs).then(function () { syncing -= 1; }, function (err) { syncing -= 1; fail(err); });
  }
  function rowZoom(row) {
    var start = parseFloat(row.getAttribute("data-start")), end = parseFloat(row.getAttribute("data-end"));
    if (!isFinite(start) || !isFinite(end)) { return; }
    zoomTo(Math.min(start, end), Math.max(start, end));
    var els = plots(), height = window.innerHeight;
    var seen = els.some(function (el) { var r = el.getBoundingClientRect(); return r.bottom > 0 && r.top < height; });
    if (!seen && els.length) { els[0].scrollIntoView({ block: "start" }); }  // show the first figure
  }
  function controls() {
    var style = document.createElement("style");
    style.textContent = "tr[data-start]{cursor:pointer}tr[data-start]:hover,tr[data-start]:focus{background:#e8f0fb}" +
      "#ls-zoom{position:fixed;right:1rem;bottom:1rem;z-index:10;background:#fff;border:1px solid #bbb;" +
      "border-radius:6px;padding:.3rem .6rem;font-size:.85rem;box-shadow:0 1px 4px rgba(0,0,0,.15)}" +
      "#ls-zoom button{margin-left:.5rem}";
    document.head.appendChild(style);
    var bar = document.createElement("div");
    bar.id = "ls-zoom";
    bar.setAttribute("role", "group");
    bar.setAttribute("aria-label", "shared time axis");
    label = document.createElement("span");
    label.setAttribute("aria-live", "polite");
    button = document.createElement("button");
    button.type = "button";
    button.id = "ls-reset-zoom";
    button.textContent = "reset zoom";
    button.addEventListener("click", reset);
    bar.appendChild(label);
    bar.appendChild(button);
    document.body.appendChild(bar);
    Array.prototype.forEach.call(document.querySelectorAll("tr[data-start]"), function (row) {
      row.tabIndex = 0;
      row.title = "zoom every figure to this interval";
      row.addEventListener("click", function () { rowZoom(row); });
      row.addEventListener("keydown", function (event) {
        if (event.key === "Enter" || event.key === " ") { event.preventDefault(); rowZoom(row); }
      });
    });
  }
  function start() {
    var els = plots();
    if (!els.length) { return; }
    initial = els.map(function (el) {
      var y = Object.keys(el.layout).filter(function (key) {
        return /^yaxis\d*$/.test(key) && !el.layout[key].fixedrange;  // not the rows' hidden span overlays
      }).map(function (key) {
        var axis = el.layout[key];
        return { key: key, auto: !!axis.autorange || !axis.range, range: axis.range ? axis.range.slice() : null };
      });
      return { el: el, x: rangeOf(el), y: y };
    });
    Array.prototype.forEach.call(document.querySelectorAll("details.detector"), function (section) {
      section.addEventListener("toggle", function () { catchUp(section); });
    });
    /* the whole log (<body data-log-span="start end">, axis units): the headline figure starts zoomed in */
    var span = (document.body.getAttribute("data-log-span") || "").split(" ").map(Number);
    var x = els[els.length - 1]._fullLayout.xaxis.range;
    full = span.length === 2 && isFinite(span[0]) && isFinite(span[1]) && span[1] > span[0] ? span :
      [axisNumber(x[0]), axisNumber(x[1])];
    controls();
    els.forEach(follow);
    var path = document.getElementById("ctx-path");
    if (path && path.on) {
      path.on("plotly_click", function (event) {
        var span = event && event.points && event.points[0] && event.points[0].customdata;
        if (span && span.length === 2) { zoomTo(Number(span[0]), Number(span[1])); }
      });
    }
    show("auto");
    document.body.setAttribute("data-time-axis", String(els.length));
  }
  function whenDrawn() {
    if (document.body.hasAttribute("data-plots-rendered")) { return start(); }
    var observer = new MutationObserver(function () {
      if (document.body.hasAttribute("data-plots-rendered")) { observer.disconnect(); start(); }
    });
    observer.observe(document.body, { attributes: true, attributeFilter: ["data-plots-rendered"] });
  }
  if (typeof Plotly !== "undefined") { whenDrawn(); }
})();
