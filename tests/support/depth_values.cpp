#include "tests/support/depth_values.hpp"

#include <cmath>
#include <cstdint>

namespace stereod::test {

DepthAgreement compareDepth(const cv::Mat& depth_mm, const nlohmann::ordered_json& metres)
{
    DepthAgreement agreement;
    for (int row = 0; row < depth_mm.rows; ++row) {
        for (int col = 0; col < depth_mm.cols; ++col) {
            const uint16_t mm = depth_mm.at<uint16_t>(row, col);
            const auto& value = metres[static_cast<std::size_t>(row) * depth_mm.cols + col];
            // NaN (null in JSON) exactly where the service has none; else within 1 mm.
            const bool same =
                mm == 0 ? value.is_null()
                        : value.is_number() && std::abs(value.get<double>() * 1000.0 - mm) <= 1.0;
            agreement.mismatched += same ? 0 : 1;
            agreement.with_depth += mm == 0 ? 0 : 1;
        }
    }
    return agreement;
}

} // namespace stereod::test
