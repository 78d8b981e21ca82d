#pragma once
// The SIMD kernel tables' targets (pipeline/sgm, pipeline/resample, pipeline/cloud): Highway
// compiles a kernel once per target and dispatches at run time. A table is made by a function of
// the caller's that reads HWY_DYNAMIC_DISPATCH of each kernel; these choose the target it sees.

#include <cstdint>
#include <vector>

#include <hwy/targets.h>

namespace stereod {

// The table of the best target this processor supports, made on the first call and kept
// (what the matchers use): the target is chosen before the table is made, so that it holds
// the chosen functions rather than the first-call trampolines. One make_table per table
// type (the table is kept per type).
template <class Table> const Table& chosenTable(Table (*make_table)())
{
    static const Table table = [make_table] {
        hwy::GetChosenTarget().Update(hwy::SupportedTargets());
        return make_table();
    }();
    return table;
}

// The table of every target Highway compiled that this processor runs (AVX2 and AVX-512
// on one x86 machine, say), best last, Highway's scalar emulation left out: what the
// kernel tests hold against the scalar reference, so that a target this machine would not
// pick is tested too. Not thread-safe: it switches Highway's chosen target while it
// collects them and sets it back, after making chosenTable() first so that the matchers'
// table is not affected.
template <class Table> std::vector<Table> tablesOfEveryTarget(Table (*make_table)())
{
    chosenTable(make_table);
    std::vector<Table> every;
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
