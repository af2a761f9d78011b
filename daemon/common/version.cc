#include "common/version.h"

#include "hg_version.h"

namespace hg::common {

const char* Version() { return HG_VERSION; }
const char* Commit() { return HG_COMMIT; }

}  // namespace hg::common
