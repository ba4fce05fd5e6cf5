#pragma once
// Statistics the tests derive their bounds from.

#include <cmath>
#include <vector>

namespace qgi::test {

/// Sample mean of independent estimates and its standard error (from the sample variance).
struct SampleMean {
    double mean = 0.0, standardError = 0.0;
};

inline SampleMean sampleMean(const std::vector<double>& values) {
    const double n = double(values.size());
    SampleMean out;
    for (double x : values)
        out.mean += x / n;
    double var = 0.0;
    for (double x : values)
        var += (x - out.mean) * (x - out.mean) / (n - 1);
    out.standardError = std::sqrt(var / n);
    return out;
}

} // namespace qgi::test
