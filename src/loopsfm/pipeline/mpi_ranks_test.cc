// The MPI entry points of a build without MPI (this test compiles mpi_ranks.cc without
// LOOPSFM_WITH_MPI, whatever the build found), and how a launched run is recognised.

#include "loopsfm/pipeline/mpi_ranks.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <string>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

TEST(MpiRanks, ABuildWithoutMpiSaysHowToGetIt) {
  EXPECT_FALSE(BuiltWithMpi());
  int argc = 0;
  char** argv = nullptr;
  try {
    StartMpi(&argc, &argv);
    FAIL() << "StartMpi did not throw";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("built without MPI"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("libopenmpi-dev"), std::string::npos) << e.what();
  }
}

TEST(MpiRanks, ALaunchedRunIsRecognisedByItsLauncherEnvironment) {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_SIZE"}) unsetenv(name);
  EXPECT_EQ(LaunchedProcessCount(), 1);
  setenv("OMPI_COMM_WORLD_SIZE", "4", 1);
  EXPECT_EQ(LaunchedProcessCount(), 4);
  unsetenv("OMPI_COMM_WORLD_SIZE");
  setenv("PMI_SIZE", "2", 1);
  EXPECT_EQ(LaunchedProcessCount(), 2);
  setenv("PMI_SIZE", "nonsense", 1);
  EXPECT_EQ(LaunchedProcessCount(), 1);
  unsetenv("PMI_SIZE");
}

}  // namespace
}  // namespace loopsfm
