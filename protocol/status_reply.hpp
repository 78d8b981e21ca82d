#pragma once
// The `status` reply (docs/protocol.md, "status"): one pure function from the values the
// service gathers to the JSON object, so that its shape is defined in one place and can
// be tested without a service.
//
// Reentrant: pure.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "model/disparity_range.hpp"
#include "model/rectified_geometry.hpp"
#include "model/region_of_interest.hpp"
#include "model/stage_timings.hpp"
#include "protocol/reading_json.hpp"
#include "protocol/reply.hpp"

namespace stereod {

// The socket server's connection counters.
struct ClientCounters {
    uint64_t connected = 0;         // open connections
    uint64_t subscribers = 0;       // connections with at least one subscription
    uint64_t accepted = 0;          // connections accepted since start
    uint64_t rejected = 0;          // turned away with too_many_clients
    uint64_t not_allowed = 0;       // turned away by socket.allow_uids / allow_gids
    uint64_t idle_closed = 0;       // disconnected after socket.idle_timeout_s of silence
    uint64_t frames_dropped = 0;    // events skipped for subscribers with unsent data
    uint64_t disconnected_slow = 0; // subscribers dropped past the backlog limit
};

// One camera in `status`.
struct StatusCamera {
    std::string name;
    std::string state;
    double fps = 0.0;
    uint64_t frames = 0;
    uint64_t dropped = 0;
    uint64_t bad_frames = 0;
    std::string last_bad_frame;
    uint64_t unpaired = 0;
    std::string last_error;
};

// The frame source in `status`.
struct StatusSource {
    std::string kind;
    std::string state;
    std::string last_error;
    std::optional<std::string> down_reason; // when the service judges the source down
    std::vector<StatusCamera> cameras;
    uint64_t pairs = 0;
    uint64_t ring_dropped = 0;
    uint64_t unpaired_dropped = 0;
    double skew_mean_ms = 0.0;
    double skew_p99_ms = 0.0;
    double skew_max_ms = 0.0;
    bool clock_offset_detected = false;
    double clock_offset_ms = 0.0;
    std::vector<std::string> warnings;
};

// The worker in `status`.
struct StatusPipeline {
    uint64_t frames = 0;
    double fps = 0.0; // 0 once frames stopped coming
    std::string matcher;
    DisparityRange range;
    uint64_t bad_frames = 0;
    uint64_t out_of_sync = 0;
    StageTimings stage_mean_ms;
    double zones_mean_ms = 0.0;
    double publish_mean_ms = 0.0;
    double latency_p50_ms = 0.0; // capture stamp to publication
    double latency_p99_ms = 0.0;
    RegionOfInterest region; // nearest.roi, fractions of the image
    // The outputs' depth cap in force (output.max_depth_m), metres; none uncalibrated.
    std::optional<double> max_output_depth_m;
};

// The numbers of the rig's calibration checks (daemon/calibration_health_monitor.hpp).
struct StatusHealthChecks {
    std::string last_check;     // the last check's own verdict, healthStateName()
    uint64_t state_changes = 0; // after the first verdict
    double row_offset_px = 0.0; // signed median of the matches, right - left
    double row_offset_p90_px = 0.0;
    double offset_px = 0.0;        // the fitted model's rows apart at the principal point
    double roll_deg = 0.0;         // its roll of the right image
    double max_row_error_px = 0.0; // its largest |row error| over the matches' area
    int matches = 0;
    double trend_px_per_min = 0.0;
    uint64_t checks = 0;
    double check_ms = 0.0;
    double interval_s = 0.0;
    std::optional<double> checked_age_s; // none before the first check
};

// The rig's calibration checks in `status`.
struct StatusCalibrationHealth {
    std::string state;                        // healthStateName()
    std::string reason;                       // empty: none
    std::optional<StatusHealthChecks> checks; // none when uncalibrated: nothing is checked
};

// The calibration in force in `status`.
struct StatusCalibration {
    std::string path;
    std::string kind = "none";                 // "none", "full" or "rectified"
    std::optional<RectifiedGeometry> geometry; // none when uncalibrated
    std::optional<double> rms_px;
    std::optional<double> epipolar_error_px;
};

// The live view (docs/live-view.md).
struct StatusLiveView {
    std::string listen; // the configured address, or "off"
    bool listening = false;
    std::string error; // why it is not listening, when it should be
    uint64_t clients = 0;
    uint64_t messages_sent = 0;
    uint64_t bytes_sent = 0;
    uint64_t readings_sent = 0;   // /stereo/nearest messages handed to clients' sockets
    uint64_t frames_dropped = 0;  // frame messages slow clients did not get
    uint64_t clients_dropped = 0; // clients closed for not reading (frames or replies)
    uint64_t refused = 0;         // requests refused: no or a wrong token, a foreign page,
                                  // too many clients, out of descriptors
};

// stereod as a ROS 2 node (docs/ros2.md).
struct StatusRos2 {
    bool enabled = false;        // ros2.enabled
    bool publishing = false;     // in the DDS domain, writers made
    std::string error;           // why it is not publishing, when it should be
    std::string ns;              // ros2.namespace
    uint32_t domain_id = 0;      // from ROS_DOMAIN_ID
    bool localhost_only = true;  // discovery on the loopback interface only
    uint64_t readers = 0;        // DDS readers matched over all topics now
    uint64_t frames = 0;         // results published
    uint64_t frames_skipped = 0; // results replaced by a newer one before they went out
    uint64_t messages = 0;       // DDS samples written
    uint64_t write_errors = 0;
};

// Everything the `status` object says, as plain values. States are the protocol's names.
struct ServiceStatus {
    double uptime_s = 0.0;
    std::string state; // "starting", "running", "source_down", "uncalibrated"
    StatusSource source;
    StatusPipeline pipeline;
    StatusCalibrationHealth calibration_health;
    StatusCalibration calibration;
    ClientCounters clients;
    StatusLiveView live_view;
    StatusRos2 ros2;
    ReadingReport reading; // its message is borrowed
    int64_t now_ns = 0;    // for the reading's age
    // publish.max_reading_age_ms: a reading older than this is stale (how a viewer that
    // holds a reading knows when to stop showing it as current).
    double max_reading_age_ms = 0.0;
};

// The `status` object (the reply's "status" member). Numbers meant to be read by people
// are rounded as docs/protocol.md gives them.
Json statusToJson(const ServiceStatus& status);

} // namespace stereod
