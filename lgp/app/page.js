// Sortable tables: click a header to sort by that column (numbers as numbers), again to reverse.
document.querySelectorAll('table.sortable').forEach(function (table) {
  table.querySelectorAll('th').forEach(function (th, col) {
    th.addEventListener('click', function () {
      var asc = !th.classList.contains('asc');
      table.querySelectorAll('th').forEach(function (h) { h.classList.remove('asc', 'desc'); });
      th.classList.add(asc ? 'asc' : 'desc');
      var body = table.tBodies[0], rows = Array.prototype.slice.call(body.rows);
      var key = function (r) { var v = r.cells[col].getAttribute('data-v'), n = Number(v); return (v !== '' && !isNaN(n)) ? n : v; };
      rows.sort(function (a, b) { var x = key(a), y = key(b); var c = (typeof x === typeof y) ? (x < y ? -1 : x > y ? 1 : 0) : (typeof x === 'number' ? -1 : 1); return asc ? c : -c; });
      rows.forEach(function (r) { body.appendChild(r); });
    });
  });
});
