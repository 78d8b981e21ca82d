#include "pipeline/calibration_health.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

namespace stereod {
namespace {

// Lowe's ratio: the best descriptor match must be clearly better than the second.
constexpr float kRatio = 0.75f;
// Matches whose row offset is this far from the median are wrong matches, not drift.
constexpr double kOutlierPx = 4.0;
// Refinement of a match: a patch of the left image around the left point is looked for
// around the right point, this far in each direction, and kept when it correlates well.
constexpr int kPatchRadius = 7;
constexpr int kSearchPx = 3;
constexpr double kMinCorrelation = 0.85;

// Parabola through three samples at -1, 0, +1: the offset of its extremum (-0.5..0.5).
double parabolaPeak(double below, double at, double above)
{
    const double curvature = below - 2.0 * at + above;
    if (curvature >= 0.0)
        return 0.0;
    return std::clamp(0.5 * (below - above) / curvature, -0.5, 0.5);
}

// ORB's keypoints sit on whole pixels of their pyramid level: too coarse for rows a
// fraction of a pixel apart. Finds the left point's patch in the right image to a tenth
// of a pixel by normalized correlation; false when it is not found clearly.
bool refine(const cv::Mat& left, const cv::Mat& right, RowMatch& match, cv::Mat& scores)
{
    const cv::Point l(cvRound(match.left.x), cvRound(match.left.y));
    const cv::Point r(cvRound(match.right.x), cvRound(match.right.y));
    const int reach = kPatchRadius + kSearchPx;
    if (l.x < kPatchRadius || l.y < kPatchRadius || l.x + kPatchRadius >= left.cols ||
        l.y + kPatchRadius >= left.rows || r.x < reach || r.y < reach ||
        r.x + reach >= right.cols || r.y + reach >= right.rows)
        return false;
    const cv::Mat patch = left(cv::Rect(l.x - kPatchRadius, l.y - kPatchRadius,
                                        2 * kPatchRadius + 1, 2 * kPatchRadius + 1));
    const cv::Mat area = right(cv::Rect(r.x - reach, r.y - reach, 2 * reach + 1, 2 * reach + 1));
    cv::matchTemplate(area, patch, scores, cv::TM_CCOEFF_NORMED);
    cv::Point best;
    double score = 0.0;
    cv::minMaxLoc(scores, nullptr, &score, nullptr, &best);
    if (score < kMinCorrelation || best.x == 0 || best.y == 0 || best.x == scores.cols - 1 ||
        best.y == scores.rows - 1)
        return false;
    const auto at = [&](int x, int y) { return static_cast<double>(scores.at<float>(y, x)); };
    const double dx =
        parabolaPeak(at(best.x - 1, best.y), at(best.x, best.y), at(best.x + 1, best.y));
    const double dy =
        parabolaPeak(at(best.x, best.y - 1), at(best.x, best.y), at(best.x, best.y + 1));
    match.left = cv::Point2f(static_cast<float>(l.x), static_cast<float>(l.y));
    match.right = cv::Point2f(static_cast<float>(r.x - kSearchPx + best.x + dx),
                              static_cast<float>(r.y - kSearchPx + best.y + dy));
    return true;
}

double median(std::vector<double> values)
{
    if (values.empty())
        return 0.0;
    const auto middle = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
    std::nth_element(values.begin(), middle, values.end());
    return *middle;
}

double percentile(std::vector<double> values, double p)
{
    if (values.empty())
        return 0.0;
    const size_t index = std::min(
        values.size() - 1,
        static_cast<size_t>(std::floor(p / 100.0 * static_cast<double>(values.size() - 1))));
    const auto nth = values.begin() + static_cast<std::ptrdiff_t>(index);
    std::nth_element(values.begin(), nth, values.end());
    return *nth;
}

// Fills the figures from `candidates` (refined matches within the row window): the
// matches on the side of the disparity the pair mostly has (positive, or negative when
// swapped), then those near the median row offset (a wrong match on a repeated pattern,
// a board's next corner say, sits pixels away), then the statistics and the verdict.
HealthMeasurement figures(const std::vector<RowMatch>& candidates, const HealthSettings& settings)
{
    HealthMeasurement m;
    size_t negative = 0;
    for (const RowMatch& match : candidates)
        negative += match.left.x - match.right.x < -0.5f;
    m.negative_disparity_fraction =
        candidates.empty() ? 0.0
                           : static_cast<double>(negative) / static_cast<double>(candidates.size());
    const bool swapped = m.negative_disparity_fraction >= settings.swapped_fraction;
    std::vector<const RowMatch*> sided;
    std::vector<double> offsets;
    for (const RowMatch& match : candidates) {
        const bool negative_side = match.left.x - match.right.x < -0.5f;
        if (negative_side != swapped)
            continue;
        sided.push_back(&match);
        offsets.push_back(match.right.y - match.left.y);
    }
    const double centre = median(offsets);
    std::vector<double> deviations;
    for (const double offset : offsets)
        deviations.push_back(std::abs(offset - centre));
    // 3 robust standard deviations (1.4826 x the median absolute deviation), never under
    // half a pixel, never over kOutlierPx.
    const double band = std::clamp(3.0 * 1.4826 * median(deviations), 0.5, kOutlierPx);
    std::vector<double> kept_offsets, magnitudes;
    for (size_t i = 0; i < sided.size(); ++i) {
        if (std::abs(offsets[i] - centre) > band)
            continue;
        m.used.push_back(*sided[i]);
        kept_offsets.push_back(offsets[i]);
        magnitudes.push_back(std::abs(offsets[i]));
    }
    m.matches = static_cast<int>(m.used.size());
    m.row_offset_px = median(kept_offsets);
    m.row_offset_p90_px = percentile(magnitudes, 90.0);
    classifyHealth(m, settings);
    return m;
}

} // namespace

const char* healthStateName(HealthState state) noexcept
{
    switch (state) {
    case HealthState::Unknown:
        return "unknown";
    case HealthState::Ok:
        return "ok";
    case HealthState::Degraded:
        return "degraded";
    case HealthState::Failed:
        return "failed";
    }
    return "unknown";
}

void classifyHealth(HealthMeasurement& m, const HealthSettings& s)
{
    if (m.matches < s.min_matches && m.negative_disparity_fraction < s.swapped_fraction) {
        m.state = HealthState::Unknown;
        m.reason = "not_enough_matches";
        return;
    }
    // Checked before the rows: swapped cameras can rectify rows perfectly well.
    if (m.negative_disparity_fraction >= s.swapped_fraction) {
        m.state = HealthState::Failed;
        m.reason = "cameras_swapped";
        return;
    }
    const double offset = std::abs(m.row_offset_px);
    if (offset <= s.ok_median_px && m.row_offset_p90_px <= s.ok_p90_px) {
        m.state = HealthState::Ok;
        m.reason.clear();
    } else if (offset >= s.failed_median_px || m.row_offset_p90_px >= 2.0 * s.failed_median_px) {
        m.state = HealthState::Failed;
        m.reason = "row_offset";
    } else {
        m.state = HealthState::Degraded;
        m.reason = "row_offset";
    }
}

struct CalibrationHealthChecker::Impl {
    explicit Impl(const HealthSettings& s)
        : settings(s), orb(cv::ORB::create(s.max_features)), matcher(cv::NORM_HAMMING)
    {
    }

    HealthSettings settings;
    cv::Ptr<cv::ORB> orb;
    cv::BFMatcher matcher;
    std::vector<cv::KeyPoint> left_points, right_points;
    cv::Mat left_descriptors, right_descriptors;
    std::vector<std::vector<cv::DMatch>> knn;
    cv::Mat scores;
};

CalibrationHealthChecker::CalibrationHealthChecker(const HealthSettings& settings)
    : impl_(std::make_unique<Impl>(settings))
{
}

CalibrationHealthChecker::~CalibrationHealthChecker() = default;

const HealthSettings& CalibrationHealthChecker::settings() const
{
    return impl_->settings;
}

HealthMeasurement CalibrationHealthChecker::measure(const cv::Mat& left, const cv::Mat& right)
{
    CV_Assert(left.type() == CV_8UC1 && right.type() == CV_8UC1 && left.size() == right.size());
    Impl& p = *impl_;
    p.orb->detectAndCompute(left, cv::noArray(), p.left_points, p.left_descriptors);
    p.orb->detectAndCompute(right, cv::noArray(), p.right_points, p.right_descriptors);
    std::vector<RowMatch> candidates;
    if (!p.left_descriptors.empty() && p.right_descriptors.rows >= 2) {
        // knnMatch appends to the vector it is given: without the clear every check would
        // also go through all earlier checks' matches, whose indices name other keypoints.
        p.knn.clear();
        p.matcher.knnMatch(p.left_descriptors, p.right_descriptors, p.knn, 2);
        for (const std::vector<cv::DMatch>& pair : p.knn) {
            if (pair.size() < 2 || pair[0].distance >= kRatio * pair[1].distance)
                continue;
            RowMatch match{p.left_points[static_cast<size_t>(pair[0].queryIdx)].pt,
                           p.right_points[static_cast<size_t>(pair[0].trainIdx)].pt};
            if (std::abs(match.right.y - match.left.y) <= p.settings.max_row_offset_px &&
                refine(left, right, match, p.scores))
                candidates.push_back(match);
        }
    }
    return figures(candidates, p.settings);
}

HealthMeasurement poolMeasurements(const std::vector<HealthMeasurement>& measurements,
                                   const HealthSettings& settings)
{
    std::vector<RowMatch> all;
    for (const HealthMeasurement& m : measurements)
        all.insert(all.end(), m.used.begin(), m.used.end());
    return figures(all, settings);
}

StereoCalibration correctRightRotation(const StereoCalibration& calibration,
                                       const std::vector<RowMatch>& matches,
                                       cv::Vec2d* rotation_deg)
{
    if (calibration.kind != StereoCalibration::Kind::Full)
        throw std::invalid_argument("a rectified-only calibration has no rotation to correct");
    constexpr size_t kMinMatches = 10;
    if (matches.size() < kMinMatches)
        throw std::invalid_argument(
            "too few matches to estimate a correction: " + std::to_string(matches.size()) +
            ", at least " + std::to_string(kMinMatches) + " needed");
    const double f = calibration.P2(0, 0);
    const double cx = calibration.P2(0, 2);
    const double cy = calibration.P2(1, 2);
    // A small rotation w of the right camera moves a rectified point at normalized (u, v)
    // to v' = v - wx (1 + v^2) + wz u + wy u v. The rows must move by -(right - left):
    // least squares for (wx, wz) over the matches, twice, dropping the worst fits.
    std::vector<const RowMatch*> inliers;
    for (const RowMatch& m : matches)
        inliers.push_back(&m);
    cv::Vec2d w(0.0, 0.0);
    for (int round = 0; round < 3; ++round) {
        cv::Mat a(static_cast<int>(inliers.size()), 2, CV_64F);
        cv::Mat b(static_cast<int>(inliers.size()), 1, CV_64F);
        for (size_t i = 0; i < inliers.size(); ++i) {
            const double u = (inliers[i]->right.x - cx) / f;
            const double v = (inliers[i]->right.y - cy) / f;
            a.at<double>(static_cast<int>(i), 0) = -(1.0 + v * v);
            a.at<double>(static_cast<int>(i), 1) = u;
            b.at<double>(static_cast<int>(i), 0) = -(inliers[i]->right.y - inliers[i]->left.y) / f;
        }
        cv::Mat x;
        cv::solve(a, b, x, cv::DECOMP_SVD);
        w = cv::Vec2d(x.at<double>(0), x.at<double>(1));
        // Keep the matches the fit explains within 3 median deviations.
        std::vector<double> residuals(inliers.size());
        for (size_t i = 0; i < inliers.size(); ++i) {
            const double u = (inliers[i]->right.x - cx) / f;
            const double v = (inliers[i]->right.y - cy) / f;
            const double predicted = (-w[0] * (1.0 + v * v) + w[1] * u) * f;
            residuals[i] = std::abs(predicted + (inliers[i]->right.y - inliers[i]->left.y));
        }
        const double spread = std::max(0.05, 3.0 * median(residuals));
        std::vector<const RowMatch*> kept;
        for (size_t i = 0; i < inliers.size(); ++i)
            if (residuals[i] <= spread)
                kept.push_back(inliers[i]);
        if (kept.size() < kMinMatches)
            break;
        inliers.swap(kept);
    }
    cv::Matx33d turn;
    cv::Rodrigues(cv::Vec3d(w[0], 0.0, w[1]), turn);
    StereoCalibration corrected = calibration;
    corrected.R2 = turn * calibration.R2;
    if (rotation_deg != nullptr)
        *rotation_deg = cv::Vec2d(w[0], w[1]) * (180.0 / CV_PI);
    return corrected;
}

} // namespace stereod
