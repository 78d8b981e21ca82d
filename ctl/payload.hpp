#pragma once
// The binary payloads that follow some replies and events of the service
// (docs/protocol.md): their descriptors, and reading image payloads into cv::Mat.
//
// Reentrant: no state; the client passed in is used by the calling thread only.

#include <cstddef>
#include <cstdint>
#include <string>

#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>

#include "ctl/client.hpp"

namespace stereod {

// One payload's descriptor (an entry of `payloads`), checked against the size its header
// announces when read.
struct Payload {
    std::string name;
    std::string format;
    int width = 0;
    int height = 0;
    std::size_t points = 0;
    std::size_t bytes = 0;
    int64_t stamp_ns = 0; // capture time of a raw frame; 0 when not given
};

// The `bytes` of a header or descriptor: 0 when absent. Throws ClientError when it is not
// a count.
std::size_t payloadBytes(const nlohmann::ordered_json& header);

// Reads a descriptor; missing fields stay at their defaults.
Payload parsePayload(const nlohmann::ordered_json& header);

// Reads an image payload of OpenCV `type` into `image` (reusing its buffer when the size
// and type match). Throws ClientError when width x height x element size is not `bytes`.
void readImagePayload(ProtocolClient& client, const Payload& payload, int type, cv::Mat& image);

} // namespace stereod
