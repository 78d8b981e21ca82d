#pragma once
// The journal's view of a camera that goes bad frame by frame. The sources count bad
// frames (corrupt MJPEG, short buffers), frames lost before pairing and frames left
// without a partner, and log none of them one by one: a camera failing every frame would
// flood the journal. This looks at those counters now and then and, per camera whose
// counts grew, makes one line saying how many of each in how long, with the latest bad
// frame's reason. At most one line per camera per interval; nothing is left out, since
// the next line counts from where the last one stopped.
//
// Thread contract: thread-bound (the event loop's tick).

#include <cstdint>
#include <string>
#include <vector>

#include "capture/frame_source.hpp"

namespace stereod {

class SourceCounterWatch {
  public:
    // `interval_ns`: the shortest time between two looks (CLOCK_MONOTONIC ns).
    explicit SourceCounterWatch(int64_t interval_ns = 5'000'000'000) noexcept;

    // Whether a look is due at `now_ns` (the first one is due at once).
    bool due(int64_t now_ns) const noexcept;

    // Compares `status` with the previous look and returns one report per camera whose
    // bad, dropped or unpaired count grew, e.g. "camera right: 75 bad frames (latest:
    // truncated JPEG), 3 frames dropped in the last 5.0 s". The first look reports what
    // the counts already hold, "since the start".
    struct Report {
        std::string text;
        bool bad_frames = false; // some frames were bad (a warning, not just information)
    };
    std::vector<Report> look(const SourceStatus& status, int64_t now_ns);

  private:
    struct Counts {
        std::string name;
        uint64_t bad_frames = 0;
        uint64_t dropped = 0;
        uint64_t unpaired = 0;
    };

    int64_t interval_ns_;
    int64_t last_look_ns_ = 0;
    bool looked_ = false;
    std::vector<Counts> last_;
};

} // namespace stereod
