"""CMG studies: steering through singularities, singular surfaces and the envelope."""
