// CPU time and peak memory of this process, for run reports and benchmarks.
#pragma once

#include <string>

namespace tessera {

double processCpuSeconds();
/// CPU time of the calling thread (a driver's I/O thread, a benchmark's client).
double threadCpuSeconds();
double peakRssMegabytes();
/// Resident memory now (/proc/self/statm) [MiB]; 0 when it cannot be read.
double currentRssMegabytes();
/// "Intel(R) Xeon(R) ... , 2 cores, 23.4 GiB, Linux 6.1" — printed by benchmarks.
std::string machineDescription();

}  // namespace tessera
