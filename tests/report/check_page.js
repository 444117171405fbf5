/* check_page.js: what tests/report/check_page.sh injects into a copy of report.html.
 * Once the page has loaded it checks what a reader would see go wrong -- an image that
 * does not load, an element wider than its box, a page wider than the window, a
 * section without its verdict, JSON text in a table cell, a comparison that shows one
 * image twice or whose slider does not move the split -- and writes the findings
 * into the element #mcp-check, which the shell script reads back from
 * `chromium --dump-dom`. */
window.addEventListener('load', function () {
  var bad = [], images = 0, figures = 0, bars = 0;
  function name(e) {
    return e.tagName.toLowerCase() + (e.id ? '#' + e.id : '') +
      (e.className && typeof e.className === 'string' ? '.' + e.className.split(' ').join('.') : '');
  }
  function where(e) {
    var s = e.closest('section');
    return s ? ' in section ' + s.id : '';
  }
  Array.prototype.forEach.call(document.images, function (img) {
    images++;
    if (img.closest('figure')) figures++;
    if (!img.complete || img.naturalWidth === 0)
      bad.push('image does not load: ' + name(img) + ' ' + img.alt + where(img));
  });
  bars = document.querySelectorAll('figure .cbar').length;
  var doc = document.documentElement, vw = doc.clientWidth;
  if (doc.scrollWidth > vw + 1)
    bad.push('the page is wider than the window: ' + doc.scrollWidth + ' > ' + vw + ' px');
  /* every element inside its parent's box, unless the parent scrolls or clips */
  document.querySelectorAll('body *').forEach(function (e) {
    var p = e.parentElement;
    if (!p || e.closest('svg') && e.tagName.toLowerCase() !== 'svg') return;
    var ov = getComputedStyle(p).overflowX;
    if (ov !== 'visible') return;
    var r = e.getBoundingClientRect(), pr = p.getBoundingClientRect();
    if (r.width === 0 && r.height === 0) return;
    if (r.right > pr.right + 1 || r.left < pr.left - 1)
      bad.push(name(e) + where(e) + ' overflows ' + name(p) + ': ' +
               Math.round(r.left) + '..' + Math.round(r.right) + ' outside ' +
               Math.round(pr.left) + '..' + Math.round(pr.right));
  });
  var sections = document.querySelectorAll('section');
  sections.forEach(function (s) {
    if (!s.querySelector(':scope > .verdict')) bad.push('section ' + s.id + ' has no verdict');
  });
  document.querySelectorAll('td').forEach(function (td) {
    var t = td.textContent.trim();
    if (!td.children.length && /^[\[{]\s*["{\[]/.test(t))
      bad.push('JSON text in a table cell' + where(td) + ': ' + t.slice(0, 60));
  });
  /* the comparison works: two different images, and the slider moves the split */
  document.querySelectorAll('.compare').forEach(function (c) {
    var r = c.querySelector('.cmp-pos'), clip = c.querySelector('.cmp-clip');
    if (c.querySelector('img.cmp-a').src === c.querySelector('img.cmp-b').src)
      bad.push('the comparison shows one image twice' + where(c));
    r.value = 25;
    r.dispatchEvent(new Event('input'));
    if (clip.style.clipPath.indexOf('75%') < 0)
      bad.push('the comparison slider does not move the split' + where(c) + ': ' +
               clip.style.clipPath);
    r.value = 50;
    r.dispatchEvent(new Event('input'));
  });
  /* the display controls: a new exposure, then false colour, redraw every HDR render
   * (a new picture) and the comparison shows the redrawn ones */
  var hdr = document.querySelectorAll('img[data-hdr]'), display = 'none';
  var bar = document.querySelector('.display');
  if (hdr.length && !bar) bad.push('HDR renders but no display controls');
  if (bar) {
    var ex = bar.querySelector('.dsp-exp'), md = bar.querySelector('.dsp-mode');
    var before = Array.prototype.map.call(hdr, function (i) { return i.src; });
    var changed = function () {
      var n = 0;
      hdr.forEach(function (img, k) { n += img.src !== before[k]; before[k] = img.src; });
      return n;
    };
    ex.value = +ex.value + 2;
    ex.dispatchEvent(new Event('input'));
    var byExposure = changed();
    md.value = 'false-colour';
    md.dispatchEvent(new Event('change'));
    var byMode = changed(), legend = !bar.querySelector('.dsp-legend').hidden;
    if (byExposure !== hdr.length)
      bad.push('exposure +2 redrew ' + byExposure + ' of ' + hdr.length + ' HDR renders');
    if (byMode !== hdr.length)
      bad.push('false colour redrew ' + byMode + ' of ' + hdr.length + ' HDR renders');
    if (!legend) bad.push('false colour shows no colour bar');
    document.querySelectorAll('.compare').forEach(function (c) {
      var a = c.querySelector('select.cmp-a').value, src = document.getElementById(a).src;
      if (document.getElementById(a).dataset.hdr && c.querySelector('img.cmp-a').src !== src)
        bad.push('the comparison does not follow the display controls' + where(c));
    });
    display = byExposure + '/' + byMode;
  }
  var compares = document.querySelectorAll('.compare:not([hidden])').length;
  var out = document.createElement('pre');
  out.id = 'mcp-check';
  out.textContent = (bad.length ? 'FAIL' : 'PASS') + ' width=' + vw + ' height=' +
    doc.scrollHeight + ' images=' + images + ' figures=' + figures + ' bars=' + bars +
    ' sections=' + sections.length + ' compares=' + compares + ' hdr=' + hdr.length +
    ' display=' + display + '\n' +
    bad.slice(0, 30).join('\n') + (bad.length > 30 ? '\n... ' + (bad.length - 30) + ' more' : '');
  document.body.appendChild(out);
});
