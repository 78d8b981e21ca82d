#pragma once
// The SIMD kernel tables' targets (pipeline/sgm, pipeline/resample): Highway compiles a
// kernel once per target and dispatches at run time. A table is made by a function of the
// caller's that reads HWY_DYNAMIC_DISPATCH of each kernel; these choose the target it sees.

#include <cstdint>
#include <vector>

#include <hwy/targets.h>

namespace stereod {

// The table of the best target this processor supports, chosen now, so that it holds the
// chosen functions rather than the first-call trampolines.
template <class MakeTable> auto tableOfChosenTarget(MakeTable make_table)
{
    hwy::GetChosenTarget().Update(hwy::SupportedTargets());
    return make_table();
}

// The table of every target Highway compiled that this processor runs (AVX2 and AVX-512
// on one x86 machine, say), best last, Highway's scalar emulation left out: what the
// kernel tests hold against the scalar reference, so that a target this machine would not
// pick is tested too. Not thread-safe: it switches Highway's chosen target while it
// collects them and sets it back; call the chosen table's function first, so that its
// table is made before.
template <class MakeTable> auto tablesOfEveryTarget(MakeTable make_table)
{
    std::vector<decltype(make_table())> every;
    const std::vector<int64_t> targets = hwy::SupportedAndGeneratedTargets();
    // Highway lists the best target first.
    for (auto target = targets.rbegin(); target != targets.rend(); ++target) {
        if (*target == HWY_SCALAR)
            continue; // the scalar reference stands for it
        hwy::SetSupportedTargetsForTest(*target);
        hwy::GetChosenTarget().Update(hwy::SupportedTargets());
        every.push_back(make_table());
    }
    hwy::SetSupportedTargetsForTest(0);
    hwy::GetChosenTarget().Update(hwy::SupportedTargets());
    return every;
}

} // namespace stereod
