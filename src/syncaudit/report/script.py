"""The reports' inline style and script: hover read-outs, linked zoom on time, map read-out.

Plain DOM code, no library: it reads each time plot's own SVG (the path data are in
data units), so there is no second copy of the data in the page. Text from the log is
only ever put into the page with textContent, never parsed as HTML.
"""

from __future__ import annotations

STYLE = """
body{font:14px/1.45 system-ui,sans-serif;margin:1.5rem auto;max-width:1040px;color:#222}
h1{font-size:1.4rem}h2{font-size:1.2rem;margin-top:2.2rem;border-bottom:1px solid #ddd}
h3{font-size:1rem;margin:1.2rem 0 .3rem}
table{border-collapse:collapse;margin:.5rem 0}td,th{border:1px solid #ccc;padding:.2rem .55rem;text-align:left}
th{background:#f3f3f3;font-weight:600}.num{text-align:right;font-variant-numeric:tabular-nums}
.pass{color:#176f2c;font-weight:600}.fail{color:#b00020;font-weight:600}
.notjudged{color:#8a5a00;font-weight:600}.warn{color:#8a5a00}
ul.notes{margin:.3rem 0;padding-left:1.2rem}
figure{margin:.6rem 0}figcaption{font-size:13px;color:#333;font-weight:600}
figcaption .unit{font-weight:400;color:#666}
.row{display:flex;flex-wrap:wrap;gap:.5rem 1rem}
svg.plot{background:#fff;font-size:11px;user-select:none}
svg.plot .grid{stroke:#ececec}svg.plot .yt{text-anchor:end;fill:#444}
svg.plot .xtick{text-anchor:middle;fill:#444}svg.plot .xlabel{text-anchor:middle;fill:#333}
svg.plot .ylabel{text-anchor:middle;fill:#333}svg.plot .legend{fill:#333}
svg.plot path.line{stroke-width:1.3px}svg.plot path.dots{stroke-width:7px;stroke-linecap:round}
svg.plot .limit{stroke:#b00020;stroke-width:1.2px;stroke-dasharray:5 3}
svg.plot .bar:not([fill]){fill:#1f5fbf}svg.plot .cursor{stroke:#555;stroke-dasharray:2 2}
svg.plot .sel{fill:#1f5fbf;fill-opacity:.12}svg.plot .hit{fill:transparent;cursor:crosshair}
.tip{position:fixed;pointer-events:none;background:#fffffff0;border:1px solid #999;
padding:.25rem .45rem;font-size:12px;white-space:pre;box-shadow:0 1px 4px #0003;z-index:5}
.hint{color:#666;font-size:12px}
svg.map path.stop{stroke-width:2.4px;stroke-linecap:round;fill:none}
ul.legend-list{list-style:none;padding:0;margin:.3rem 0;font-size:12px;line-height:1.6}
.swatch,.mark{display:inline-block;width:10px;height:10px;margin-right:.4rem;vertical-align:-1px}
.swatch,.mark.disc,.mark.ring{border-radius:50%}.mark.ring{width:6px;height:6px;border:2px solid}
.mark.bar{height:3px;vertical-align:3px}
"""

SCRIPT = r"""
(function () {
  'use strict';
  var started = performance.now();
  var NS = 'http://www.w3.org/2000/svg';
  var t0ms = Number(document.body.getAttribute('data-t0-ms'));
  var tip = document.createElement('div');
  tip.className = 'tip';
  tip.hidden = true;
  document.body.appendChild(tip);
  function parse(path) {
    var nums = (path.getAttribute('d') || '').match(/-?\d+(?:\.\d+)?(?:e[-+]?\d+)?/gi) || [];
    var step = path.classList.contains('dots') ? 4 : 2;
    var xs = [], ys = [];
    for (var i = 0; i + 1 < nums.length; i += step) {
      xs.push(Number(nums[i]));
      ys.push(-Number(nums[i + 1]));
    }
    return {xs: xs, ys: ys, label: path.getAttribute('data-label') || ''};
  }
  function nice(lo, hi, count) {
    if (!(hi > lo)) return [lo];
    var raw = (hi - lo) / count, p = Math.pow(10, Math.floor(Math.log10(raw)));
    var step = [1, 2, 5, 10].map(function (m) { return m * p; }).find(function (s) { return s >= raw; });
    var out = [];
    for (var v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) {
      out.push(Math.abs(v) < step * 1e-9 ? 0 : v);
    }
    return out;
  }
  function fmt(v) {  // six significant digits: 3,007.19 us, 0.123456 ms
    if (!isFinite(v)) return '-';
    return Number(v.toPrecision(6)).toLocaleString('en-US', {maximumFractionDigits: 6});
  }
  function nearest(xs, t) {
    var lo = 0, hi = xs.length - 1;
    if (hi < 0) return -1;
    while (hi - lo > 1) {
      var mid = (lo + hi) >> 1;
      if (xs[mid] < t) lo = mid; else hi = mid;
    }
    return Math.abs(xs[lo] - t) <= Math.abs(xs[hi] - t) ? lo : hi;
  }
  var plots = [], total = 0;
  document.querySelectorAll('figure.tplot').forEach(function (fig) {
    var svg = fig.querySelector('svg.plot'), area = svg.querySelector('svg.area');
    var series = Array.prototype.map.call(area.querySelectorAll('path'), parse);
    var n = series.reduce(function (a, s) { return a + s.xs.length; }, 0);
    fig.setAttribute('data-rendered-points', String(n));
    total += n;
    var x = Number(area.getAttribute('x')), y = Number(area.getAttribute('y'));
    var w = Number(area.getAttribute('width')), h = Number(area.getAttribute('height'));
    var hit = document.createElementNS(NS, 'rect');
    [['x', x], ['y', y], ['width', w], ['height', h], ['class', 'hit']].forEach(function (a) {
      hit.setAttribute(a[0], String(a[1]));
    });
    var cursor = document.createElementNS(NS, 'line');
    cursor.setAttribute('class', 'cursor');
    cursor.setAttribute('y1', String(y));
    cursor.setAttribute('y2', String(y + h));
    cursor.style.display = 'none';
    var sel = document.createElementNS(NS, 'rect');
    sel.setAttribute('class', 'sel');
    sel.setAttribute('y', String(y));
    sel.setAttribute('height', String(h));
    sel.style.display = 'none';
    svg.appendChild(cursor);
    svg.appendChild(sel);
    svg.appendChild(hit);
    var vb = area.viewBox.baseVal;
    var p = {fig: fig, svg: svg, area: area, series: series, x: x, y: y, w: w, h: h,
             home: [vb.x, vb.x + vb.width], unit: fig.getAttribute('data-unit') || ''};
    plots.push(p);
    function timeAt(ev) {
      var r = hit.getBoundingClientRect();
      return vb.x + (ev.clientX - r.left) / r.width * vb.width;
    }
    function pxOf(t) { return x + (t - vb.x) / vb.width * w; }
    var drag = null;
    hit.addEventListener('mousedown', function (ev) { drag = timeAt(ev); ev.preventDefault(); });
    hit.addEventListener('mousemove', function (ev) {
      var t = timeAt(ev);
      if (drag !== null) {
        var a = pxOf(Math.min(drag, t)), b = pxOf(Math.max(drag, t));
        sel.setAttribute('x', String(a));
        sel.setAttribute('width', String(Math.max(b - a, 0)));
        sel.style.display = '';
      }
      var lines = ['t = ' + t.toFixed(3) + ' s' +
                   (isFinite(t0ms) ? '  (' + new Date(t0ms + t * 1000).toISOString() + ')' : '')];
      series.forEach(function (s) {
        var i = nearest(s.xs, t);
        if (i >= 0) lines.push(s.label + ': ' + fmt(s.ys[i]) + ' ' + p.unit + '  @ ' + s.xs[i].toFixed(3) + ' s');
      });
      tip.textContent = lines.join('\n');
      tip.hidden = false;
      tip.style.left = (ev.clientX + 14) + 'px';
      tip.style.top = (ev.clientY + 14) + 'px';
      cursor.setAttribute('x1', String(pxOf(t)));
      cursor.setAttribute('x2', String(pxOf(t)));
      cursor.style.display = '';
    });
    hit.addEventListener('mouseleave', function () {
      tip.hidden = true; cursor.style.display = 'none'; sel.style.display = 'none'; drag = null;
    });
    hit.addEventListener('mouseup', function (ev) {
      if (drag === null) return;
      var t = timeAt(ev), a = Math.min(drag, t), b = Math.max(drag, t);
      drag = null;
      sel.style.display = 'none';
      if ((b - a) / vb.width * w > 3) zoom(a, b);
    });
    hit.addEventListener('dblclick', function () {
      plots.forEach(function (q) { setRange(q, q.home[0], q.home[1]); });
      try { history.replaceState(null, '', location.pathname); } catch (e) { /* no history */ }
    });
  });
  function setRange(p, a, b) {
    var vb = p.area.viewBox.baseVal;
    vb.x = a;
    vb.width = b - a;
    var g = p.svg.querySelector('g.xt');
    while (g.firstChild) g.removeChild(g.firstChild);
    var ticks = nice(a, b, 10);
    var step = ticks.length > 1 ? ticks[1] - ticks[0] : 1;
    var decimals = step < 1 ? Math.min(9, -Math.floor(Math.log10(step) + 1e-9)) : 0;
    ticks.forEach(function (t) {
      var px = p.x + (t - a) / (b - a) * p.w;
      var line = document.createElementNS(NS, 'line');
      line.setAttribute('class', 'grid');
      line.setAttribute('x1', String(px)); line.setAttribute('x2', String(px));
      line.setAttribute('y1', String(p.y)); line.setAttribute('y2', String(p.y + p.h));
      var text = document.createElementNS(NS, 'text');
      text.setAttribute('class', 'xtick');
      text.setAttribute('x', String(px)); text.setAttribute('y', String(p.y + p.h + 14));
      text.textContent = t.toLocaleString('en-US', {minimumFractionDigits: decimals, maximumFractionDigits: decimals});
      g.appendChild(line); g.appendChild(text);
    });
  }
  function zoom(a, b) {
    plots.forEach(function (p) { setRange(p, a, b); });
    try { history.replaceState(null, '', '#t=' + a.toFixed(3) + '-' + b.toFixed(3)); } catch (e) { /* no history */ }
  }
  // Maps from above: hover reads the cursor's x, y and the nearest point's stop.
  var mapPoints = 0;
  document.querySelectorAll('figure[data-kind="top-view"]').forEach(function (fig) {
    var map = fig.querySelector('svg.map'), inner = map.querySelector('svg.points');
    var xs = [], ys = [], stops = [];
    inner.querySelectorAll('path.stop').forEach(function (path) {
      var d = path.getAttribute('d') || '', stop = path.getAttribute('data-stop'), mm;
      var dot = /M(-?\d+(?:\.\d+)?),(-?\d+(?:\.\d+)?)h0/g;  // u = -y, v = -x
      while ((mm = dot.exec(d)) !== null) {
        xs.push(-Number(mm[2])); ys.push(-Number(mm[1])); stops.push(stop);
      }
    });
    fig.setAttribute('data-rendered-points', String(xs.length));
    mapPoints += xs.length;
    map.addEventListener('mousemove', function (ev) {
      var m = inner.getScreenCTM();
      if (!m) return;
      var at = new DOMPoint(ev.clientX, ev.clientY).matrixTransform(m.inverse());
      var x = -at.y, y = -at.x, best = -1, bestD = Infinity;
      for (var i = 0; i < xs.length; i++) {
        var d = (xs[i] - x) * (xs[i] - x) + (ys[i] - y) * (ys[i] - y);
        if (d < bestD) { bestD = d; best = i; }
      }
      var lines = ['x ' + x.toFixed(2) + ' m, y ' + y.toFixed(2) + ' m'];
      if (best >= 0 && Math.sqrt(bestD) * m.a <= 12) {
        lines.push('stop ' + stops[best] + ': x ' + xs[best].toFixed(2) + ' m, y ' + ys[best].toFixed(2) + ' m');
      }
      tip.textContent = lines.join('\n');
      tip.hidden = false;
      tip.style.left = (ev.clientX + 14) + 'px';
      tip.style.top = (ev.clientY + 14) + 'px';
    });
    map.addEventListener('mouseleave', function () { tip.hidden = true; });
  });
  document.body.setAttribute('data-map-points', String(mapPoints));
  // A link to a time window: report.html#t=12.5-14 opens zoomed to 12.5 s .. 14 s.
  var linked = /^#t=(-?[\d.]+)-(-?[\d.]+)$/.exec(location.hash);
  if (linked && Number(linked[2]) > Number(linked[1])) zoom(Number(linked[1]), Number(linked[2]));
  document.body.setAttribute('data-points', String(total));
  document.body.setAttribute('data-script-ms', (performance.now() - started).toFixed(1));
  document.body.setAttribute('data-ready', 'yes');
})();
"""
