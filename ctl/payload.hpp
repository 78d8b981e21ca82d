#pragma once
// Reading the binary payloads of the service's replies and events (protocol/payload.hpp)
// off a client's connection, with the checks that keep a confused peer from making the
// client read too much or too little.
//
// Reentrant: no state; the client passed in is used by the calling thread only.

#include <cstddef>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>

#include "ctl/client.hpp"
#include "model/cloud_point.hpp"
#include "protocol/payload.hpp"

namespace stereod {

// The `bytes` of a header or descriptor: 0 when absent. Throws ClientError when it is not
// a count.
std::size_t payloadBytes(const nlohmann::ordered_json& header);

// Reads a descriptor; missing fields stay at their defaults. Throws ClientError when its
// `bytes` is not a count.
Payload parsePayload(const nlohmann::ordered_json& header);

// Reads an image payload of OpenCV `type` into `image` (reusing its buffer when the size
// and type match). Throws ClientError when width x height x element size is not `bytes`.
void readImagePayload(ProtocolClient& client, const Payload& payload, int type, cv::Mat& image);

// Reads a cloud payload into `cloud`. Throws ClientError when its bytes are not 16 per
// point.
void readCloudPayload(ProtocolClient& client, const Payload& payload,
                      std::vector<CloudPoint>& cloud);

// Reads a u8_rgb image payload into `bgr` as CV_8UC3 BGR (OpenCV's order), empty for a
// 0 x 0 one (a camera that kept no colour). Throws ClientError when it does not add up.
void readColourPayload(ProtocolClient& client, const Payload& payload, cv::Mat& bgr);

// Reads a u8_rgb per-point payload (cloud_colour) into `colours`. Throws ClientError when
// its bytes are not 3 per point.
void readCloudColourPayload(ProtocolClient& client, const Payload& payload,
                            std::vector<CloudColour>& colours);

} // namespace stereod
