#include "pipeline/calibration_health.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/core/hal/hal.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "base/percentile.hpp"
#include "pipeline/calibration_formats.hpp"

namespace stereod {
namespace {

// Lowe's ratio: the best descriptor match must be clearly better than the second.
constexpr float kRatio = 0.75f;
// Refinement of a match: a patch of the left image around the left point is looked for
// around the right point, this far in each direction, and kept when it correlates well.
constexpr int kPatchRadius = 7;
constexpr int kSearchPx = 3;
constexpr double kMinCorrelation = 0.85;
// Then to a fraction of a pixel on the same patch (subpixel(): iterations, the step that
// counts as converged in px), and dropped when that moves it by a pixel or more: it did
// not settle on the correlation's peak.
constexpr int kSubpixelIterations = 10;
constexpr double kSubpixelEpsPx = 0.001;
constexpr float kSubpixelMaxMovePx = 1.0f;

// ORB's keypoints sit on whole pixels of their pyramid level: too coarse for rows a
// fraction of a pixel apart. Finds the left point's patch in the right image to the
// pixel by normalized correlation, the left point put on its pixel; false when it is not
// found clearly (a weak or an edge peak).
bool correlate(const cv::Mat& left, const cv::Mat& right, RowMatch& match, cv::Mat& scores)
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
    match.left = cv::Point2f(static_cast<float>(l.x), static_cast<float>(l.y));
    match.right = cv::Point2f(static_cast<float>(r.x - kSearchPx + best.x),
                              static_cast<float>(r.y - kSearchPx + best.y));
    return true;
}

// Solves the symmetric positive definite system a x = b; false when it is not. OpenCV's
// Cholesky directly: cv::solve costs more in its bookkeeping than the 4x4 itself, and it
// is called for every iteration of every match.
bool solve4(cv::Matx44d a, const cv::Vec4d& b, cv::Vec4d& x)
{
    x = b;
    return cv::hal::Cholesky64f(a.val, 4 * sizeof(double), 4, x.val, sizeof(double), 1);
}

// Bilinear sample of a CV_32F image at (x, y), which must lie at least one pixel inside.
float sample(const cv::Mat& image, float x, float y)
{
    const int x0 = static_cast<int>(std::floor(x));
    const int y0 = static_cast<int>(std::floor(y));
    const float fx = x - static_cast<float>(x0);
    const float fy = y - static_cast<float>(y0);
    const float* top = image.ptr<float>(y0) + x0;
    const float* bottom = image.ptr<float>(y0 + 1) + x0;
    return (1.0f - fy) * ((1.0f - fx) * top[0] + fx * top[1]) +
           fy * ((1.0f - fx) * bottom[0] + fx * bottom[1]);
}

// The right point of a match to a fraction of a pixel: Gauss-Newton on
// sum over the patch of (gain * right(x + t) + bias - left(x))^2 for the shift t, with a
// gain and a bias so that cameras of different exposure still agree (Lucas-Kanade with
// photometric terms). Unlike a parabola through the correlation's three samples, which
// pulls offsets towards whole pixels ("pixel locking": a roll of 0.3 deg read as
// 0.17 deg on a 232 px wide image), it interpolates the image itself. False when it does
// not settle within kSubpixelMaxMovePx of the correlation's peak.
bool subpixel(const cv::Mat& left, const cv::Mat& right, const cv::Mat& right_dx,
              const cv::Mat& right_dy, RowMatch& match)
{
    const cv::Point l(cvRound(match.left.x), cvRound(match.left.y));
    const cv::Point2f start = match.right;
    cv::Point2f at = start;
    double gain = 1.0, bias = 0.0;
    const float margin = static_cast<float>(kPatchRadius) + kSubpixelMaxMovePx + 1.0f;
    for (int iteration = 0; iteration < kSubpixelIterations; ++iteration) {
        if (at.x < margin || at.y < margin || at.x >= right.cols - margin ||
            at.y >= right.rows - margin)
            return false;
        cv::Matx44d normal = cv::Matx44d::zeros();
        cv::Vec4d gradient(0.0, 0.0, 0.0, 0.0);
        for (int v = -kPatchRadius; v <= kPatchRadius; ++v) {
            const uint8_t* row = left.ptr<uint8_t>(l.y + v);
            for (int u = -kPatchRadius; u <= kPatchRadius; ++u) {
                const float x = at.x + static_cast<float>(u);
                const float y = at.y + static_cast<float>(v);
                const double value = sample(right, x, y);
                const cv::Vec4d jacobian(gain * sample(right_dx, x, y),
                                         gain * sample(right_dy, x, y), value, 1.0);
                const double error = row[l.x + u] - (gain * value + bias);
                normal += jacobian * jacobian.t();
                gradient += error * jacobian;
            }
        }
        cv::Vec4d step;
        if (!solve4(normal, gradient, step))
            return false; // no texture to align on
        at += cv::Point2f(static_cast<float>(step[0]), static_cast<float>(step[1]));
        gain += step[2];
        bias += step[3];
        if (std::hypot(step[0], step[1]) < kSubpixelEpsPx)
            break;
    }
    if (cv::norm(at - start) >= kSubpixelMaxMovePx)
        return false;
    match.right = at;
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
    return lowerLinearPercentile(values.begin(), values.end(), p);
}

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegreesPerRadian = 180.0 / kPi;

// The robust fit. RANSAC: offset and roll from 2 matches at a time, this many times,
// scored by how many matches they explain within kAgreePx (each match counted up to that
// distance, MSAC); the seed is fixed so that the same matches always give the same model.
// The search leaves out the vertical scale and the yaw: with them a model can bend to pass
// through two groups of matches in different parts of the image, the right ones and a
// group a period off.
constexpr int kModelTerms = 4;
constexpr int kSearchTerms = 2;
constexpr int kSearchRounds = 300;
constexpr uint64_t kSearchSeed = 0x5eed;
constexpr double kAgreePx = 1.0;
// Then iteratively reweighted least squares of all four terms with Tukey's biweight at
// 4.685 robust standard deviations (95 % efficiency on Gaussian noise); the deviation never
// below kMinSpreadPx, the refinement's own precision, so that a few perfect matches do not
// shut out the rest.
constexpr int kReweightRounds = 10;
constexpr double kTukey = 4.685;
constexpr double kMinSpreadPx = 0.1;
// The vertical scale and the yaw move rows only in proportion to the row, and to column
// times row over f: the matches of one pair, often in a few clusters, hardly tell them
// from noise and from each other. Each has a prior, zero with this standard deviation (a
// ridge on the least squares): they are fitted when the matches show them clearly and stay
// near zero when not. A tenth of a percent of focal length between the two cameras is a
// change of focus; a tenth of a degree of yaw moves the rows of the demo's wide-angle rig
// (f 515 px at 640x480) by a quarter of a pixel in its corners, and those of a lens of
// 40 degrees by a twentieth of that. Without the priors, matches all on one side of the
// image let yaw (column times row) stand in for roll (column) and scale for offset.
constexpr double kScalePrior = 0.001;
constexpr double kYawPriorRad = 0.1 / 180.0 * kPi;
// The matches the final model explains: within 3 robust deviations, at least 0.5 px and
// at most kAgreePx.
constexpr double kMinBandPx = 0.5;

// Where the model's terms are measured from: the right image's principal point.
struct ModelFrame {
    double focal_px;
    double cx_px; // right image: cx + doffs
    double cy_px;
};

ModelFrame frameOf(const RectifiedGeometry& g)
{
    return {g.focal_px, g.cx_px + g.doffs_px, g.cy_px};
}

// The model's terms at a point of the right image: dy = terms . (offset, tan roll,
// vertical scale, yaw).
cv::Vec4d terms(const ModelFrame& frame, double x, double y)
{
    const double u = (x - frame.cx_px) / frame.focal_px;
    const double v = (y - frame.cy_px) / frame.focal_px;
    const double f = frame.focal_px;
    return {1.0 + v * v, -f * u, f * v, -f * u * v};
}

double rowOffset(const RowMatch& match)
{
    return static_cast<double>(match.right.y) - static_cast<double>(match.left.y);
}

double residual(const cv::Vec4d& parameters, const ModelFrame& frame, const RowMatch& match)
{
    return rowOffset(match) - terms(frame, match.right.x, match.right.y).dot(parameters);
}

// Weighted least squares of the four terms with the priors of scale and yaw, for residuals
// of standard deviation spread_px; false when the matches do not determine offset and roll
// (fewer than two with weight, or all in one column).
bool solveWeighted(const std::vector<RowMatch>& matches, const std::vector<double>& weights,
                   const ModelFrame& frame, double spread_px, ModelTerms which,
                   cv::Vec4d& parameters)
{
    cv::Matx44d normal = cv::Matx44d::zeros();
    cv::Vec4d right_side(0.0, 0.0, 0.0, 0.0);
    int weighted = 0;
    for (size_t i = 0; i < matches.size(); ++i) {
        if (weights[i] <= 0.0)
            continue;
        ++weighted;
        const cv::Vec4d t = terms(frame, matches[i].right.x, matches[i].right.y);
        normal += weights[i] * (t * t.t());
        right_side += weights[i] * rowOffset(matches[i]) * t;
    }
    if (weighted < kSearchTerms)
        return false;
    const double variance = spread_px * spread_px;
    if (which == ModelTerms::PitchAndRoll) {
        // Scale and yaw held at 0: their rows and columns of the system left out.
        for (int k = 2; k < kModelTerms; ++k) {
            for (int j = 0; j < kModelTerms; ++j)
                normal(k, j) = normal(j, k) = 0.0;
            normal(k, k) = 1.0;
            right_side[k] = 0.0;
        }
    } else {
        normal(2, 2) += variance / (kScalePrior * kScalePrior);
        normal(3, 3) += variance / (kYawPriorRad * kYawPriorRad);
    }
    cv::Vec4d solution;
    if (!solve4(normal, right_side, solution))
        return false;
    for (int k = 0; k < kModelTerms; ++k)
        if (!std::isfinite(solution[k]))
            return false;
    parameters = solution;
    return true;
}

// RANSAC over pairs of matches for offset and roll; false when no pair gives a model.
bool searchModel(const std::vector<RowMatch>& matches, const ModelFrame& frame, cv::Vec4d& best)
{
    const int n = static_cast<int>(matches.size());
    cv::RNG random(kSearchSeed);
    double best_cost = std::numeric_limits<double>::infinity();
    for (int round = 0; round < kSearchRounds; ++round) {
        const int a = random.uniform(0, n);
        const int b = random.uniform(0, n - 1);
        const RowMatch& first = matches[static_cast<size_t>(a)];
        const RowMatch& second = matches[static_cast<size_t>(b >= a ? b + 1 : b)];
        const cv::Vec4d ta = terms(frame, first.right.x, first.right.y);
        const cv::Vec4d tb = terms(frame, second.right.x, second.right.y);
        const double determinant = ta[0] * tb[1] - ta[1] * tb[0];
        // Two matches in nearly one column say nothing about the roll.
        if (std::abs(determinant) < 1e-9 * frame.focal_px)
            continue;
        const double ya = rowOffset(first), yb = rowOffset(second);
        const cv::Vec4d candidate((ya * tb[1] - yb * ta[1]) / determinant,
                                  (ta[0] * yb - tb[0] * ya) / determinant, 0.0, 0.0);
        double cost = 0.0;
        for (const RowMatch& match : matches) {
            const double r = residual(candidate, frame, match);
            cost += std::min(r * r, kAgreePx * kAgreePx);
            if (cost >= best_cost)
                break;
        }
        if (cost < best_cost) {
            best_cost = cost;
            best = candidate;
        }
    }
    return std::isfinite(best_cost);
}

// 1.4826 x the median |residual| of the matches within `band` of the model: a robust
// standard deviation of the ones it explains.
double robustSpread(const std::vector<double>& residuals, double band)
{
    std::vector<double> within;
    for (const double r : residuals)
        if (std::abs(r) <= band)
            within.push_back(std::abs(r));
    return std::max(kMinSpreadPx, 1.4826 * median(within));
}

// The model's largest |row offset| at the matches it explains.
void largestRowError(const std::vector<RowMatch>& inliers, RowOffsetModel& model)
{
    model.max_row_error_px = 0.0;
    model.row_error_px = 0.0;
    for (const RowMatch& match : inliers) {
        const double dy = model.rowOffsetAt(match.right);
        if (std::abs(dy) > model.max_row_error_px) {
            model.max_row_error_px = std::abs(dy);
            model.row_error_px = dy;
        }
    }
}

// ORB finds many corners at two or three levels of its pyramid, and correlate() puts them
// on the same pixel: the copies would count as more evidence than they are. Keeps one
// match per left pixel, and none of those whose right point another left point also
// matched (within a pixel): on a repeating pattern one of the two is a period off, and
// nothing tells which.
std::vector<RowMatch> oneToOne(std::vector<RowMatch> candidates)
{
    const auto pixel = [](cv::Point2f p) { return std::pair(cvRound(p.x), cvRound(p.y)); };
    std::stable_sort(
        candidates.begin(), candidates.end(),
        [&](const RowMatch& a, const RowMatch& b) { return pixel(a.left) < pixel(b.left); });
    candidates.erase(std::unique(candidates.begin(), candidates.end(),
                                 [&](const RowMatch& a, const RowMatch& b) {
                                     return pixel(a.left) == pixel(b.left);
                                 }),
                     candidates.end());
    // In order of the right point's column, each compared with those less than a pixel to
    // its right.
    std::vector<size_t> order(candidates.size());
    std::iota(order.begin(), order.end(), size_t{0});
    std::sort(order.begin(), order.end(),
              [&](size_t a, size_t b) { return candidates[a].right.x < candidates[b].right.x; });
    std::vector<bool> shared(candidates.size(), false);
    for (size_t i = 0; i < order.size(); ++i) {
        const cv::Point2f& here = candidates[order[i]].right;
        for (size_t j = i + 1; j < order.size(); ++j) {
            const cv::Point2f& there = candidates[order[j]].right;
            if (there.x - here.x >= 1.0f)
                break;
            if (std::abs(there.y - here.y) < 1.0f)
                shared[order[i]] = shared[order[j]] = true;
        }
    }
    std::vector<RowMatch> kept;
    for (size_t i = 0; i < candidates.size(); ++i)
        if (!shared[i])
            kept.push_back(candidates[i]);
    return kept;
}

// Fills the figures from `candidates` (refined matches within the row window): the
// matches on the side of the disparity the pair mostly has (positive, or negative when
// swapped), then the model fitted to them, the matches it explains, the statistics and the
// verdict.
HealthMeasurement figures(const std::vector<RowMatch>& candidates,
                          const RectifiedGeometry& geometry, const HealthSettings& settings)
{
    HealthMeasurement m;
    size_t negative = 0;
    for (const RowMatch& match : candidates)
        negative += match.left.x - match.right.x < -0.5f;
    m.negative_disparity_fraction =
        candidates.empty() ? 0.0
                           : static_cast<double>(negative) / static_cast<double>(candidates.size());
    const bool swapped = m.negative_disparity_fraction >= settings.swapped_fraction;
    std::vector<RowMatch> sided;
    for (const RowMatch& match : candidates) {
        const bool negative_side = match.left.x - match.right.x < -0.5f;
        if (negative_side == swapped)
            sided.push_back(match);
    }
    if (fitRowOffsetModel(sided, geometry, m.model, &m.used)) {
        std::vector<double> offsets, magnitudes;
        for (const RowMatch& match : m.used) {
            offsets.push_back(rowOffset(match));
            magnitudes.push_back(std::abs(rowOffset(match)));
        }
        m.row_offset_px = median(offsets);
        m.row_offset_p90_px = percentile(magnitudes, 90.0);
    }
    m.matches = static_cast<int>(m.used.size());
    classifyHealth(m, settings);
    return m;
}

} // namespace

const char* healthStateName(HealthState state) noexcept
{
    return kHealthStates.name(state, "unknown");
}

double RowOffsetModel::rowOffsetAt(cv::Point2d right) const
{
    const ModelFrame frame{focal_px, right_principal_px.x, right_principal_px.y};
    const cv::Vec4d parameters(pitch_px, std::tan(roll_deg / kDegreesPerRadian), vertical_scale,
                               yaw_deg / kDegreesPerRadian);
    return terms(frame, right.x, right.y).dot(parameters);
}

bool fitRowOffsetModel(const std::vector<RowMatch>& matches, const RectifiedGeometry& geometry,
                       RowOffsetModel& model, std::vector<RowMatch>* inliers, ModelTerms terms)
{
    const ModelFrame frame = frameOf(geometry);
    cv::Vec4d parameters;
    if (matches.size() < static_cast<size_t>(kModelTerms) ||
        !searchModel(matches, frame, parameters))
        return false;
    std::vector<double> residuals(matches.size()), weights(matches.size());
    double band = kAgreePx;
    for (int round = 0; round < kReweightRounds; ++round) {
        for (size_t i = 0; i < matches.size(); ++i)
            residuals[i] = residual(parameters, frame, matches[i]);
        const double spread = robustSpread(residuals, band);
        const double cutoff = kTukey * spread;
        band = cutoff;
        for (size_t i = 0; i < matches.size(); ++i) {
            const double ratio = residuals[i] / cutoff;
            weights[i] =
                std::abs(ratio) < 1.0 ? (1.0 - ratio * ratio) * (1.0 - ratio * ratio) : 0.0;
        }
        cv::Vec4d next;
        if (!solveWeighted(matches, weights, frame, spread, terms, next))
            break;
        const bool settled = cv::norm(next - parameters) < 1e-6;
        parameters = next;
        if (settled)
            break;
    }
    for (size_t i = 0; i < matches.size(); ++i)
        residuals[i] = residual(parameters, frame, matches[i]);
    const double spread = robustSpread(residuals, band);
    const double keep = std::clamp(3.0 * spread, kMinBandPx, kAgreePx);
    std::vector<RowMatch> kept;
    std::vector<double> kept_residuals;
    for (size_t i = 0; i < matches.size(); ++i)
        if (std::abs(residuals[i]) <= keep) {
            kept.push_back(matches[i]);
            kept_residuals.push_back(std::abs(residuals[i]));
        }
    if (kept.size() < static_cast<size_t>(kModelTerms))
        return false;
    model = RowOffsetModel{};
    model.focal_px = frame.focal_px;
    model.right_principal_px = {frame.cx_px, frame.cy_px};
    model.pitch_px = parameters[0];
    model.roll_deg = std::atan(parameters[1]) * kDegreesPerRadian;
    model.vertical_scale = parameters[2];
    model.yaw_deg = parameters[3] * kDegreesPerRadian;
    model.offset_px = model.rowOffsetAt(
        {(geometry.image_size.width - 1) / 2.0, (geometry.image_size.height - 1) / 2.0});
    model.residual_px = 1.4826 * median(kept_residuals);
    largestRowError(kept, model);
    if (inliers != nullptr)
        *inliers = std::move(kept);
    return true;
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
    const double row_error = m.model.max_row_error_px;
    const double roll = std::abs(m.model.roll_deg);
    // A roll beyond its own limit is named as the cause: the rows are apart because the
    // right camera turned about its axis.
    const char* cause = roll >= s.degraded_roll_deg ? "roll" : "row_offset";
    if (std::abs(m.model.offset_px) >= s.failed_offset_px || row_error >= s.failed_row_error_px ||
        roll >= s.failed_roll_deg) {
        m.state = HealthState::Failed;
        m.reason = cause;
    } else if (row_error > s.ok_row_error_px || roll >= s.degraded_roll_deg) {
        m.state = HealthState::Degraded;
        m.reason = cause;
    } else {
        m.state = HealthState::Ok;
        m.reason.clear();
    }
}

struct CalibrationHealthChecker::Impl {
    Impl(const RectifiedGeometry& g, const HealthSettings& s)
        : geometry(g), settings(s), orb(cv::ORB::create(s.max_features)), matcher(cv::NORM_HAMMING)
    {
    }

    RectifiedGeometry geometry;
    HealthSettings settings;
    cv::Ptr<cv::ORB> orb;
    cv::BFMatcher matcher;
    std::vector<cv::KeyPoint> left_points, right_points;
    cv::Mat left_descriptors, right_descriptors;
    std::vector<std::vector<cv::DMatch>> knn;
    cv::Mat scores;
    cv::Mat right_float, right_dx, right_dy; // the right image and its gradient, CV_32F
};

CalibrationHealthChecker::CalibrationHealthChecker(const RectifiedGeometry& geometry,
                                                   const HealthSettings& settings)
    : impl_(std::make_unique<Impl>(geometry, settings))
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
        right.convertTo(p.right_float, CV_32F);
        cv::Scharr(p.right_float, p.right_dx, CV_32F, 1, 0, 1.0 / 32.0);
        cv::Scharr(p.right_float, p.right_dy, CV_32F, 0, 1, 1.0 / 32.0);
        p.matcher.knnMatch(p.left_descriptors, p.right_descriptors, p.knn, 2);
        for (const std::vector<cv::DMatch>& pair : p.knn) {
            if (pair.size() < 2 || pair[0].distance >= kRatio * pair[1].distance)
                continue;
            RowMatch match{p.left_points[static_cast<size_t>(pair[0].queryIdx)].pt,
                           p.right_points[static_cast<size_t>(pair[0].trainIdx)].pt};
            if (std::abs(match.right.y - match.left.y) <= p.settings.max_row_offset_px &&
                correlate(left, right, match, p.scores) &&
                subpixel(left, p.right_float, p.right_dx, p.right_dy, match))
                candidates.push_back(match);
        }
    }
    return figures(oneToOne(candidates), p.geometry, p.settings);
}

HealthMeasurement
CalibrationHealthChecker::pool(const std::vector<HealthMeasurement>& measurements) const
{
    std::vector<RowMatch> all;
    for (const HealthMeasurement& m : measurements)
        all.insert(all.end(), m.used.begin(), m.used.end());
    return figures(all, impl_->geometry, impl_->settings);
}

StereoCalibration correctRightRotation(const StereoCalibration& calibration,
                                       const std::vector<RowMatch>& matches,
                                       cv::Vec2d* rotation_deg)
{
    constexpr size_t kMinMatches = 10;
    RowOffsetModel model;
    if (matches.size() < kMinMatches || !fitRowOffsetModel(matches, calibration.rectified, model,
                                                           nullptr, ModelTerms::PitchAndRoll))
        throw std::invalid_argument(
            "too few matches to estimate a correction: " + std::to_string(matches.size()) +
            ", at least " + std::to_string(kMinMatches) + " that agree on the rows needed");
    // Turning the right camera by w (radians) about its rectified x and z axes moves its
    // rows by -f [w_x (1 + v^2) - w_z u]: the model's pitch (offset / f) and roll, undone.
    const cv::Vec2d w(model.pitch_px / model.focal_px, model.roll_deg / kDegreesPerRadian);
    cv::Matx33d turn;
    cv::Rodrigues(cv::Vec3d(w[0], 0.0, w[1]), turn);
    StereoCalibration corrected = calibration.kind == StereoCalibration::Kind::Full
                                      ? calibration
                                      : fullFromRectified(calibration);
    corrected.R2 = turn * corrected.R2;
    if (rotation_deg != nullptr)
        *rotation_deg = w * kDegreesPerRadian;
    return corrected;
}

} // namespace stereod
