// What the page says about a reading, decided in one place: the state (a name the page's
// styles and tests key on), the large text, and the line under it. Pure: no DOM.
//
// States:
//   waiting       connected, no reading yet
//   valid         a distance (with LEFT EDGE when part of the region cannot see that near)
//   suspect       a distance, but the service suspects its calibration (calibration_suspect)
//   nearer        nearer_than_range: something is nearer than the range can see
//   none          no reading, with the reason's code and message
//   stale         the newest reading is older than max_reading_age_ms (by the page's clock,
//                 or the service's reason `stale`), or the page lost its connection: the
//                 last value greyed, after the word STALE
//   disconnected  never connected, or the connection is gone and no reading was shown

// `reading`: the reading object of docs/protocol.md, or null; `ageMs`: its age now;
// `maxAgeMs`: the service's publish.max_reading_age_ms; `connected`: the WebSocket is open.
export function readingView(reading, ageMs, maxAgeMs, connected) {
  if (!reading) {
    return connected ? { state: "waiting", text: "waiting for a reading…", detail: "" }
                     : { state: "disconnected", text: "connecting…", detail: "" };
  }
  const reason = reading.reason || {};
  const number = reading.valid ? `${reading.distance_m.toFixed(3)} m` : null;
  const tooOld = ageMs > maxAgeMs;
  if (tooOld || !connected || reason.code === "stale") {
    // The last value stays in sight, greyed and marked, so nobody takes it for a fresh one.
    const last = number ?? `NO READING: ${reason.code || "unknown"}`;
    const why = !connected ? "the connection is lost"
              : `${(ageMs / 1000).toFixed(1)} s old, ${(maxAgeMs / 1000).toFixed(1)} s allowed`;
    return { state: "stale", text: `STALE ${last}`, detail: `no fresh reading: ${why}` };
  }
  if (reading.valid) {
    // Part of the region the image's left edge cuts short of the distance (docs/protocol.md).
    const leftEdge = reading.out_of_view_fraction > 0
      ? `LEFT EDGE: ${(100 * reading.out_of_view_fraction).toFixed(0)} % of the region ` +
        "cannot see this near" : "";
    if (reading.calibration_suspect) {
      const rows = typeof reading.calibration_row_offset_px === "number"
        ? `: rows ${reading.calibration_row_offset_px >= 0 ? "+" : ""}` +
          `${reading.calibration_row_offset_px.toFixed(2)} px apart` : "";
      return { state: "suspect", text: number,
               detail: `CALIBRATION SUSPECT${rows}; the distance may be wrong` +
                       (leftEdge ? `; ${leftEdge}` : "") };
    }
    return { state: "valid", text: number, detail: leftEdge };
  }
  if (reason.code === "nearer_than_range") {
    const bound = typeof reading.nearer_than_m === "number"
      ? `NEARER THAN ${reading.nearer_than_m.toFixed(2)} m` : "NEARER THAN THE RANGE";
    return { state: "nearer", text: bound, detail: reason.message || "" };
  }
  return { state: "none", text: `NO READING: ${reason.code || "unknown"}`,
           detail: reason.message || "" };
}
