// The browser viewer of vts serve (GET /{tileset}/, docs/PROTOCOL.md): reads the tileset's
// TileJSON and shows its standard image tiles (/{tileset}/{z}/{x}/{y}.png) with OpenLayers (the
// global `ol` of the embedded dist/ol.js). A plain image is shown in pixel space (its top-left
// corner at the origin, levels 0..max_zoom, no wrap); a georeferenced one on a map in its own grid:
// EPSG:4326 for WorldCRS84Quad (our level z = TMS level z - 1: level 0 is one tile of 360 x 360
// degrees whose top half is the world), EPSG:3857 for WebMercatorQuad (our level = XYZ level).
// State for tests and scripts: window.vtsViewer.
(function () {
  'use strict';
  const WEB_MERCATOR_HALF = 20037508.342789244;
  const IMAGE_TILE = 256; // every standard image tile is 256 x 256 pixels
  const state = {
    status: 'loading', // 'loading' | 'ready' | 'error'
    error: null,
    kind: null, // 'pixels' | 'WorldCRS84Quad' | 'WebMercatorQuad'
    tiles: { loading: 0, loaded: 0, failed: 0 },
    renders: 0, // rendercomplete events: a render with every wanted tile loaded
    wantedView: null, // { center, resolution } setPixelView() asked for last
    readout: '',
    map: null,
    grid: null,
  };
  window.vtsViewer = state;

  const mapDiv = document.getElementById('map');
  const readout = document.getElementById('vts-readout');

  function fail(message) {
    state.status = 'error';
    state.error = message;
    readout.textContent = message;
    readout.classList.add('vts-error');
  }

  // The grid of a tileset: OpenLayers projection, origin, resolutions (units per image pixel at
  // each of our levels) and the extent that holds tiles.
  function gridOf(tj) {
    const v = tj.vtstream || {};
    const maxZoom = v.max_zoom;
    const geo = v.georeference;
    const levels = [];
    if (!geo) {
      // Units: texels of the finest level, y up (so the image is [0, -height] .. [width, 0]).
      const side = v.tile_size * Math.pow(2, maxZoom);
      for (let z = 0; z <= maxZoom; z++) levels.push(side / Math.pow(2, z) / IMAGE_TILE);
      const projection = new ol.proj.Projection({
        code: 'vts-pixels', units: 'pixels', extent: [0, -side, side, 0],
      });
      const extent = [0, -v.height, v.width, 0];
      return { kind: 'pixels', projection, origin: [0, 0], resolutions: levels, extent, maxZoom };
    }
    const b = geo.bounds;
    if (geo.tiling === 'WorldCRS84Quad') {
      for (let z = 0; z <= maxZoom; z++) levels.push(360 / Math.pow(2, z) / IMAGE_TILE);
      return {
        kind: geo.tiling, projection: ol.proj.get('EPSG:4326'), origin: [-180, 90],
        resolutions: levels, extent: [b[0], b[1], b[2], b[3]], maxZoom,
      };
    }
    if (geo.tiling === 'WebMercatorQuad') {
      for (let z = 0; z <= maxZoom; z++) levels.push(2 * WEB_MERCATOR_HALF / Math.pow(2, z) / IMAGE_TILE);
      const extent = ol.proj.transformExtent([b[0], b[1], b[2], b[3]], 'EPSG:4326', 'EPSG:3857');
      return {
        kind: geo.tiling, projection: ol.proj.get('EPSG:3857'),
        origin: [-WEB_MERCATOR_HALF, WEB_MERCATOR_HALF], resolutions: levels, extent, maxZoom,
      };
    }
    throw new Error('unknown tiling "' + geo.tiling + '"');
  }

  function formatReadout(grid, coordinate) {
    if (grid.kind === 'pixels') {
      return 'x ' + Math.floor(coordinate[0]) + ', y ' + Math.floor(-coordinate[1]);
    }
    const lonLat = grid.kind === 'WebMercatorQuad'
      ? ol.proj.toLonLat(coordinate, 'EPSG:3857') : coordinate;
    return 'lon ' + lonLat[0].toFixed(6) + ', lat ' + lonLat[1].toFixed(6);
  }

  function show(tj) {
    const grid = gridOf(tj);
    state.kind = grid.kind;
    state.grid = grid;
    // Tiles of route (A), next to the TileJSON: "<name>/{z}/{x}/{y}.png" relative to it.
    const tilejsonUrl = new URL(mapDiv.dataset.tilejson, document.baseURI);
    const tileBase = new URL(encodeURIComponent(mapDiv.dataset.tileset) + '/', tilejsonUrl);
    const tileGrid = new ol.tilegrid.TileGrid({
      origin: grid.origin, resolutions: grid.resolutions, extent: grid.extent,
      tileSize: IMAGE_TILE,
    });
    const source = new ol.source.XYZ({
      projection: grid.projection,
      tileGrid,
      wrapX: false,
      interpolate: false, // one texel is one square of screen pixels, as archived
      transition: 0,
      tileUrlFunction: (c) => tileBase.href + c[0] + '/' + c[1] + '/' + c[2] + '.png',
    });
    source.on('tileloadstart', () => { state.tiles.loading++; });
    source.on('tileloadend', () => { state.tiles.loading--; state.tiles.loaded++; });
    source.on('tileloaderror', () => { state.tiles.loading--; state.tiles.failed++; });
    const view = new ol.View({
      projection: grid.projection,
      resolutions: grid.resolutions,
      constrainResolution: true,
      extent: grid.extent,
      showFullExtent: true,
      multiWorld: grid.kind === 'pixels',
    });
    const map = new ol.Map({
      target: mapDiv,
      layers: [new ol.layer.Tile({ source, extent: grid.extent })],
      view,
    });
    view.fit(grid.extent, { size: map.getSize() });
    // Counts frames of the view setPixelView() asked for last: a frame of the view before it,
    // completing just after the call (its tiles loaded, the new view's not yet started), is not
    // a render of the new view.
    map.on('rendercomplete', (e) => {
      const shown = e.frameState && e.frameState.viewState;
      const wanted = state.wantedView;
      if (wanted && shown) {
        const res = wanted.resolution;
        const dc = Math.hypot(shown.center[0] - wanted.center[0],
          shown.center[1] - wanted.center[1]);
        if (Math.abs(shown.resolution - res) > 1e-9 * res || dc > 1e-6 * res) return;
      }
      state.renders++;
    });
    map.on('pointermove', (e) => {
      state.readout = formatReadout(grid, e.coordinate);
      readout.textContent = state.readout;
    });
    state.map = map;
    state.status = 'ready';
  }

  // Shows image pixel (px, py) of level z at the viewport's top-left corner, one image pixel per
  // CSS pixel; returns the number of renders so far (wait for state.renders to exceed it: it
  // counts only complete renders of this view from now on).
  state.setPixelView = function (z, px, py) {
    const grid = state.grid;
    const res = grid.resolutions[z];
    const size = state.map.getSize();
    const view = state.map.getView();
    const before = state.renders;
    view.setResolution(res);
    view.setCenter([grid.origin[0] + (px + size[0] / 2) * res,
      grid.origin[1] - (py + size[1] / 2) * res]);
    state.wantedView = { center: view.getCenter(), resolution: view.getResolution() };
    return before;
  };

  fetch(mapDiv.dataset.tilejson, { headers: { Accept: 'application/json' } })
    .then((r) => {
      if (!r.ok) throw new Error(r.url + ' answered ' + r.status);
      return r.json();
    })
    .then(show)
    .catch((e) => fail('cannot show this tileset: ' + e.message));
})();
