#pragma once
// MPI ranks (OpenMPI, MPICH): the processes `mpirun -np N loopsfm ...` or `srun` starts.
// Present when the build found MPI (libopenmpi-dev); without it, BuiltWithMpi() is false
// and StartMpi throws, so the program can say how to get it.

#include <memory>

#include "loopsfm/pipeline/ranks.h"

namespace loopsfm {

bool BuiltWithMpi();

// How many processes a launcher started for this run, from the environment it sets
// (OpenMPI's mpirun, or PMI under MPICH and Slurm); 1 when none did.
int LaunchedProcessCount();

// Starts MPI (all MPI calls then come from this thread) and returns this process's ranks;
// MPI is finalised when they are destroyed. Throws Error when the build has no MPI.
std::unique_ptr<Ranks> StartMpi(int* argc, char*** argv);

}  // namespace loopsfm
