#include "model/reading.hpp"

namespace stereod {

const char* reasonCode(NoReadingReason reason) noexcept
{
    return kReasonCodes.name(reason, "unknown");
}

const char* reasonText(NoReadingReason reason) noexcept
{
    switch (reason) {
    case NoReadingReason::None:
        return "valid reading";
    case NoReadingReason::NoFrameYet:
        return "no frame processed yet";
    case NoReadingReason::TooFewValidPixels:
        return "too few valid pixels in the region";
    case NoReadingReason::NothingInRange:
        return "nothing within the depth range in the region";
    case NoReadingReason::OutOfSync:
        return "cameras out of sync";
    case NoReadingReason::SourceDown:
        return "frame source down";
    case NoReadingReason::BadFrame:
        return "the frame pair could not be processed";
    case NoReadingReason::Stale:
        return "the latest reading is too old";
    case NoReadingReason::Uncalibrated:
        return "the service runs without a calibration";
    case NoReadingReason::NearerThanRange:
        return "something in the region is nearer than the disparity range can see";
    case NoReadingReason::CalibrationSuspect:
        return "the calibration no longer rectifies the cameras (calibration health failed)";
    }
    return "unknown";
}

bool meansNotProducing(NoReadingReason reason) noexcept
{
    switch (reason) {
    case NoReadingReason::NoFrameYet:
    case NoReadingReason::OutOfSync:
    case NoReadingReason::SourceDown:
    case NoReadingReason::Stale:
    case NoReadingReason::Uncalibrated:
        return true;
    default:
        return false;
    }
}

} // namespace stereod
